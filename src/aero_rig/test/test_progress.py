"""The campaign's progress: a bar on a terminal, one line per state change or interval in a log."""

import io

from aero_rig.cli.progress import Progress, line


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _spins(progress: Progress, clock: Clock, states: list[tuple[float, int, str]]) -> None:
    for t, k, state in states:
        clock.t = 100.0 + t
        progress.update(k, 13_764 if k else 0, state)


# four spins a second: 4 s starting, 90 s collecting, then a refit and the end
SPINS = [(0.25 * i, 0, "") for i in range(16)]
SPINS += [(4 + 0.25 * i, 25 * i, "collecting") for i in range(1, 360)]
SPINS += [(95.0, 13_764, "refitting"), (95.2, 13_764, "refitting"), (99.0, 13_764, "done")]


def test_a_log_gets_a_line_per_state_change_or_interval_and_no_carriage_return() -> None:
    log, clock = io.StringIO(), Clock()
    progress = Progress(quiet=False, stream=log, interval_s=30.0, clock=clock)
    _spins(progress, clock, SPINS)
    progress.write("aero-rig: warning: the lift node is silent")
    progress.close()
    text = log.getvalue()
    assert "\r" not in text
    assert text.splitlines() == [
        "experiment: 0 samples, plan not yet received, starting, 0 s",
        "experiment: 0 % (25 of 13,764 samples), collecting, 4 s",
        "experiment: 22 % (3,025 of 13,764 samples), collecting, 34 s",
        "experiment: 44 % (6,025 of 13,764 samples), collecting, 64 s",
        "experiment: 100 % (13,764 of 13,764 samples), refitting, 95 s",
        "experiment: 100 % (13,764 of 13,764 samples), done, 99 s",
        "aero-rig: warning: the lift node is silent",
    ]


def test_a_terminal_gets_the_bar_redrawn_in_place() -> None:
    tty, clock = Terminal(), Clock()
    progress = Progress(quiet=False, stream=tty, clock=clock)
    _spins(progress, clock, SPINS[:40])  # 16 starting, 24 collecting
    progress.close()
    text = tty.getvalue()
    assert text.count("\r") >= 40
    assert "collecting" in text
    assert "experiment: 0 samples" not in text  # the bar, not the plain lines


def test_quiet_shows_no_progress_but_still_the_warnings() -> None:
    for stream in (io.StringIO(), Terminal()):
        clock = Clock()
        progress = Progress(quiet=True, stream=stream, clock=clock)
        _spins(progress, clock, SPINS)
        progress.write("aero-rig: warning: stalled")
        progress.close()
        assert stream.getvalue() == "aero-rig: warning: stalled\n"


def test_line_without_a_plan_yet() -> None:
    assert (
        line(0, 0, "starting", 1.4) == "experiment: 0 samples, plan not yet received, starting, 1 s"
    )
