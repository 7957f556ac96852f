"""Optional outputs of `vmax-sim evaluate` that watch the rollouts: the failure gallery and the difficulty report.

Both are `on_batch` hooks of `compare_policies` (called after every batch of every policy with the
host batch and the rollout); `EvaluationExtras` chains the ones asked for and writes their results.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

from vmax_sim.evaluation.difficulty import DifficultyCollector
from vmax_sim.evaluation.gallery import GalleryCollector


def chain_hooks(*hooks: Callable | None) -> Callable | None:
    """One on_batch hook calling each given one in turn (None when none is given)."""
    active = [hook for hook in hooks if hook is not None]
    if not active:
        return None

    def on_batch(*args):
        for hook in active:
            hook(*args)

    return on_batch


@dataclasses.dataclass
class EvaluationExtras:
    gallery: GalleryCollector | None = None
    gallery_dir: Path | None = None
    difficulty: DifficultyCollector | None = None

    @classmethod
    def create(cls, gallery_dir: str | None = None, gallery_max: int = 50, gallery_passed: int = 5,
               difficulty: bool = False) -> EvaluationExtras:
        return cls(gallery=GalleryCollector(gallery_max, gallery_passed) if gallery_dir else None,
                   gallery_dir=Path(gallery_dir) if gallery_dir else None,
                   difficulty=DifficultyCollector() if difficulty else None)

    @property
    def on_batch(self) -> Callable | None:
        return chain_hooks(self.gallery, self.difficulty)

    def finish(self, runs: Sequence, out: str | None = None, *, show_tables: bool = True, progress: bool = True,
               print_fn: Callable[[str], None] = print, note: str = "") -> None:
        """Prints the difficulty table (after the comparison), writes difficulty CSVs into an `out` directory
        (not for an `out` .json file), and renders the gallery."""
        if self.difficulty is not None:
            if show_tables:
                print_fn("\nAccuracy and V-Max score by difficulty (docs/evaluation-reports.md):\n")
                print_fn(self.difficulty.markdown(runs))
            if out and not out.endswith(".json"):
                self.difficulty.write(out, runs)
                if show_tables:
                    print_fn(f"wrote {out}/difficulty.csv and difficulty-scenarios.csv")
        if self.gallery is not None:
            index = self.gallery.write(self.gallery_dir, runs, progress=progress, note=note)
            if show_tables:
                print_fn(f"wrote the failure gallery {index}")
