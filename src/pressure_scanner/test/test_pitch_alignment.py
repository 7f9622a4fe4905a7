"""Pitch by stamp for taps samples: exact, interpolated within the gap, waiting, bounded."""

import math

import pytest

from pressure_scanner.pitch_alignment import PitchAlignment

MS = 1_000_000  # ns


def _isnan(alpha: float | None) -> bool:
    """NaN: the pitch cannot be known (None, not known yet, is not NaN)."""
    return alpha is not None and math.isnan(alpha)


def test_exact_stamp_takes_that_state_even_across_a_long_gap() -> None:
    align = PitchAlignment(max_gap_ns=0, max_pending=10)
    align.add_pitch(0, 0.1)
    align.add_pitch(1000 * MS, 0.3)
    assert align.add_sample(1000 * MS, "taps") == [(1000 * MS, "taps", 0.3)]
    assert align.add_sample(0, "first") == [(0, "first", 0.1)]
    assert align.pending_count == 0


def test_interpolates_linearly_between_neighbours_within_the_gap() -> None:
    align = PitchAlignment(max_gap_ns=10 * MS, max_pending=10)
    align.add_pitch(0, 1.0)
    align.add_pitch(10 * MS, 3.0)  # gap == max_gap: still interpolated
    [(stamp, payload, alpha)] = align.add_sample(int(2.5 * MS), "taps")
    assert (stamp, payload) == (int(2.5 * MS), "taps")
    assert alpha == pytest.approx(1.5)
    assert align.alpha(int(7.5 * MS), final=False) == pytest.approx(2.5)


def test_gap_longer_than_max_gap_gives_nan_at_once() -> None:
    align = PitchAlignment(max_gap_ns=20 * MS, max_pending=10)
    align.add_pitch(0, 1.0)
    align.add_pitch(20 * MS + 1, 2.0)
    [(_, _, alpha)] = align.add_sample(10 * MS, "taps")
    assert math.isnan(alpha)
    assert align.pending_count == 0  # NaN is final: nothing to wait for


def test_sample_ahead_of_the_newest_pitch_waits_and_later_samples_queue_behind_it() -> None:
    align = PitchAlignment(max_gap_ns=20 * MS, max_pending=10)
    align.add_pitch(0, 1.0)
    assert align.alpha(5 * MS, final=False) is None
    assert align.add_sample(5 * MS, "ahead") == []
    assert align.add_sample(0, "known") == []  # its pitch is known, but order holds
    assert align.add_sample(15 * MS, "further") == []
    assert align.pending_count == 3
    released = align.add_pitch(10 * MS, 3.0)
    assert [(s, p) for s, p, _ in released] == [(5 * MS, "ahead"), (0, "known")]
    assert released[0][2] == pytest.approx(2.0)
    assert released[1][2] == 1.0
    assert align.pending_count == 1
    [(stamp, payload, alpha)] = align.add_pitch(20 * MS, 5.0)
    assert (stamp, payload) == (15 * MS, "further")
    assert alpha == pytest.approx(4.0)
    assert align.pending_count == 0


def test_sample_waits_for_the_first_pitch() -> None:
    align = PitchAlignment(max_gap_ns=20 * MS, max_pending=10)
    assert align.add_sample(0, "taps") == []
    assert align.add_pitch(0, 0.5) == [(0, "taps", 0.5)]


def test_overflow_forces_the_oldest_out_with_final_semantics() -> None:
    align = PitchAlignment(max_gap_ns=10 * MS, max_pending=2)
    align.add_pitch(0, 1.0)
    assert align.add_sample(5 * MS, "a") == []
    assert align.add_sample(50 * MS, "b") == []
    # within max_gap after the newest pitch: final takes the newest value
    assert align.add_sample(60 * MS, "c") == [(5 * MS, "a", 1.0)]
    # beyond max_gap after the newest pitch: final gives NaN
    [(stamp, payload, alpha)] = align.add_sample(70 * MS, "d")
    assert (stamp, payload) == (50 * MS, "b") and math.isnan(alpha)
    assert align.pending_count == 2


def test_overflow_without_any_pitch_gives_nan() -> None:
    align = PitchAlignment(max_gap_ns=10 * MS, max_pending=1)
    assert align.add_sample(0, "a") == []
    [(stamp, payload, alpha)] = align.add_sample(1 * MS, "b")
    assert (stamp, payload) == (0, "a") and math.isnan(alpha)
    assert align.alpha(0, final=True) is None  # as the node always had it: None = not known


def test_stamp_before_the_history_is_decided_at_once_and_blocks_nothing() -> None:
    """Pitch stamps only grow: a sample older than the oldest state can never get a better
    answer, so it must not wait (it would hold every later sample in the queue: the rig's
    scanner starting before its actuator would give NaN coefficients for the whole run)."""
    align = PitchAlignment(max_gap_ns=10 * MS, max_pending=5000)
    align.add_pitch(100 * MS, 1.0)
    align.add_pitch(110 * MS, 2.0)
    assert align.alpha(95 * MS, final=False) == 1.0  # within the gap: the oldest state
    assert _isnan(align.alpha(50 * MS, final=False))
    (early,) = align.add_sample(50 * MS, "early")
    assert early[1] == "early" and math.isnan(early[2])
    assert align.add_sample(105 * MS, "later") == [(105 * MS, "later", pytest.approx(1.5))]
    assert align.pending_count == 0


def test_out_of_order_and_repeated_pitch_stamps_are_ignored() -> None:
    align = PitchAlignment(max_gap_ns=20 * MS, max_pending=10)
    align.add_pitch(10 * MS, 1.0)
    align.add_pitch(20 * MS, 2.0)
    assert align.add_sample(25 * MS, "waiting") == []
    assert align.add_pitch(20 * MS, 5.0) == []  # repeated
    assert align.add_pitch(15 * MS, 9.0) == []  # out of order
    assert list(align.stamps) == [10 * MS, 20 * MS]
    assert align.alpha(20 * MS, final=False) == 2.0
    assert align.alpha(15 * MS, final=False) == pytest.approx(1.5)
    assert align.pending_count == 1


def test_flush_releases_everything_pending_as_final() -> None:
    align = PitchAlignment(max_gap_ns=10 * MS, max_pending=10)
    align.add_pitch(0, 1.0)
    align.add_sample(5 * MS, "near")
    align.add_sample(30 * MS, "far")
    released = align.flush()
    assert [(s, p) for s, p, _ in released] == [(5 * MS, "near"), (30 * MS, "far")]
    assert released[0][2] == 1.0 and math.isnan(released[1][2])
    assert align.pending_count == 0
    assert align.flush() == []


def test_history_is_bounded_and_the_exact_lookup_with_it() -> None:
    align = PitchAlignment(max_gap_ns=5 * MS, max_pending=10, history=3)
    for k in range(10):
        align.add_pitch(k * MS, float(k))
        assert len(align.by_stamp) <= 3
    assert list(align.stamps) == [7 * MS, 8 * MS, 9 * MS]
    assert sorted(align.by_stamp) == list(align.stamps)
    assert _isnan(align.alpha(0, final=False))  # dropped: can no longer be known
    assert _isnan(align.alpha(0, final=True))
    assert align.alpha(8 * MS, final=False) == 8.0


def test_rejects_nonsense_bounds() -> None:
    with pytest.raises(ValueError, match="history"):
        PitchAlignment(max_gap_ns=0, max_pending=1, history=0)
    with pytest.raises(ValueError):
        PitchAlignment(max_gap_ns=-1, max_pending=1)


def test_lift_node_gap_in_ns_keeps_the_seconds_comparison() -> None:
    from pressure_scanner.lift_node import gap_ns

    for seconds in (0.0, 0.02, 0.1, 1e-9, 0.3, 1.7):
        bound = gap_ns(seconds)
        for d in (bound - 1, bound, bound + 1):
            assert (d <= seconds * 1e9) == (d <= bound)
    assert gap_ns(math.inf) > 2**63
