"""The progress display of long commands: plain periodic lines in a log, a tqdm bar on a terminal, nothing when off."""

from __future__ import annotations

import io

from scenariomax.progress import Progress, format_duration, progress_line


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _log_progress(clock: FakeClock, **kwargs) -> tuple[Progress, io.StringIO]:
    stream = io.StringIO()
    progress = Progress("converting", kwargs.pop("total", 400), "scenarios", stream=stream, is_tty=False,
                        interval_s=10.0, clock=clock, **kwargs)
    return progress, stream


def test_a_log_gets_a_plain_line_every_interval_with_total_rate_and_eta():
    clock = FakeClock()
    progress, stream = _log_progress(clock)
    clock.now += 5
    progress.update(60)
    assert stream.getvalue() == ""  # the interval has not passed yet
    clock.now += 5
    progress.update(60)
    assert stream.getvalue() == "converting: 120/400 scenarios (30%), 12.0/s, ETA 0:00:23\n"
    clock.now += 3
    progress.update(30)
    assert stream.getvalue().count("\n") == 1  # 3 s after the last line: nothing new
    clock.now += 10
    progress.set_postfix(failures=2)
    progress.update(10)
    progress.close()
    lines = stream.getvalue().splitlines()
    assert lines[1] == "converting: 160/400 scenarios (40%), 7.0/s, ETA 0:00:34, failures=2"
    assert lines[2] == "converting: 160/400 scenarios (40%), 7.0/s, done in 0:00:23, failures=2"
    assert "\r" not in stream.getvalue()


def test_without_a_total_the_lines_count_without_an_eta():
    clock = FakeClock()
    progress, stream = _log_progress(clock, total=None)
    clock.now += 10
    progress.update(25)
    assert stream.getvalue() == "converting: 25 scenarios, 2.5/s\n"


def test_a_resumed_run_rates_only_this_sessions_units():
    clock = FakeClock()
    progress, stream = _log_progress(clock, initial=300)
    clock.now += 10
    progress.update(50)
    assert stream.getvalue() == "converting: 350/400 scenarios (87%), 5.0/s, ETA 0:00:10\n"


def test_an_error_inside_the_with_block_leaves_the_error_as_the_last_line():
    clock = FakeClock()
    progress, stream = _log_progress(clock)
    try:
        with progress:
            progress.update(5)
            raise ValueError("bad input")
    except ValueError:
        pass
    assert stream.getvalue() == ""


def test_a_terminal_gets_a_tqdm_bar_with_total_and_eta():
    stream = io.StringIO()
    with Progress("evaluating", 10, "scenarios", stream=stream, is_tty=True, leave=True) as progress:
        assert progress.is_bar
        progress.update(4)
        progress.set_postfix(policy="idm")
    frames = stream.getvalue()
    assert "\r" in frames and "evaluating" in frames
    assert "4/10" in frames and "40%" in frames
    assert "<" in frames  # tqdm's "elapsed<remaining": the ETA
    assert "policy=idm" in frames


def test_quiet_shows_nothing_but_still_counts():
    stream = io.StringIO()
    with Progress("converting", 10, "scenarios", enabled=False, stream=stream, is_tty=True, interval_s=0) as progress:
        progress.update(3)
        progress.set_postfix(failures=1)
    assert stream.getvalue() == "" and progress.done == 3 and not progress.is_bar


def test_line_format_helpers():
    assert format_duration(3725.4) == "1:02:05"
    assert progress_line("x", 0, 10, "scenarios", 0.0) == "x: 0/10 scenarios (0%), 0.0/s"  # no ETA from no rate


def test_reaching_the_total_leaves_the_last_word_to_the_final_line():
    clock = FakeClock()
    progress, stream = _log_progress(clock, total=4)
    clock.now += 20
    progress.update(4)
    assert stream.getvalue() == ""
    progress.close()
    assert stream.getvalue() == "converting: 4/4 scenarios (100%), 0.2/s, done in 0:00:20\n"
