"""Optional outputs of `vmax-sim evaluate` that watch the rollouts: the failure gallery, the difficulty report and
the rollout viewer page (`--view`).

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
    view: object | None = None  # a vmax_sim.evaluation.rollout_view.RolloutCollector
    view_file: Path | None = None

    @classmethod
    def create(cls, gallery_dir: str | None = None, gallery_max: int = 50, gallery_passed: int = 5,
               difficulty: bool = False, view_file: str | None = None, view_max: int = 8) -> EvaluationExtras:
        view = None
        if view_file:
            from vmax_sim.evaluation.rollout_view import RolloutCollector

            view = RolloutCollector(view_max, prefer_failures=True)
        return cls(gallery=GalleryCollector(gallery_max, gallery_passed) if gallery_dir else None,
                   gallery_dir=Path(gallery_dir) if gallery_dir else None,
                   difficulty=DifficultyCollector() if difficulty else None,
                   view=view, view_file=Path(view_file) if view_file else None)

    @property
    def on_batch(self) -> Callable | None:
        return chain_hooks(self.gallery, self.difficulty, self.view)

    def finish(self, runs: Sequence, out: str | None = None, *, show_tables: bool = True, progress: bool = True,
               print_fn: Callable[[str], None] = print, note: str = "", data: str | None = None,
               mode_name: str = "non_reactive") -> None:
        """Prints the difficulty table (after the comparison), writes difficulty CSVs into an `out` directory
        (not for an `out` .json file), renders the gallery and writes the viewer page (logged scenes read
        from `data`)."""
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
        if self.view is not None and data:
            from vmax_sim.evaluation.rollout_view import write_collected_view

            result = write_collected_view(self.view, [run.name for run in runs], data, self.view_file, mode_name)
            print_fn(f"wrote the rollout viewer {result.out} ({result.num_embedded} scenario(s), failed first)")
