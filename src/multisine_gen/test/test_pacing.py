"""The generator's pacing (pacing.py): wall clock and credit window, with explicit times."""

from multisine_gen.pacing import StreamPacer


def test_nothing_before_t0() -> None:
    pacer = StreamPacer(total=100, fs=200.0, real_time_factor=0.0)
    assert pacer.target(5.0) == 0


def test_wall_clock_pacing() -> None:
    pacer = StreamPacer(total=1000, fs=200.0, real_time_factor=1.0)
    pacer.start(10.0)
    assert pacer.target(10.0) == 1  # sample 0 is due at t0
    assert pacer.target(10.5) == 101
    assert pacer.target(100.0) == 1000  # never past the plan
    fast = StreamPacer(total=1000, fs=200.0, real_time_factor=2.0)
    fast.start(0.0)
    assert fast.target(0.5) == 201


def test_credit_window_bounds_the_lead() -> None:
    pacer = StreamPacer(
        total=10_000, fs=200.0, real_time_factor=0.0, flow_control=True, max_lead=50
    )
    pacer.start(0.0)
    assert pacer.target(1.0) == 50  # nothing came back yet: 50 samples in flight at most
    pacer.credit(9)
    assert pacer.target(1.0) == 60
    pacer.credit(5)  # an older sample coming back late does not take credit away
    assert pacer.target(1.0) == 60
    pacer.credit(10_500)
    assert pacer.target(1.0) == 10_000


def test_credit_and_clock_together_take_the_smaller() -> None:
    pacer = StreamPacer(
        total=10_000, fs=200.0, real_time_factor=1.0, flow_control=True, max_lead=50
    )
    pacer.start(0.0)
    pacer.credit(1000)
    assert pacer.target(0.1) == 21  # the clock limits
    assert pacer.target(100.0) == 1051  # the credit limits
