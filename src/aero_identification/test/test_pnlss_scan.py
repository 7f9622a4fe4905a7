"""The cross-validated PNLSS structure scan on systems whose structure is known."""

import sys
from pathlib import Path

import numpy as np
import pytest

from aero_identification import scan_pnlss
from aero_identification.periodic_data import PeriodicData
from aero_identification.scan import (
    ScanRow,
    candidate_grid,
    cross_fit,
    fit_candidate,
    select_one_se,
)
from aero_identification.subspace import fit_linear_ss

sys.path.insert(0, str(Path(__file__).parent))
from test_pnlss_duffing import LINES, N, P, make_case, robust_bla  # the Duffing cases


def _split(k3: float, seed: int) -> tuple[PeriodicData, PeriodicData, dict]:
    """Realization 0 for training, 1 for validation; linear models of every order from the
    BLA of both (the scan's default would use the training data alone, which has M = 1)."""
    case = make_case(k3=k3, seed=seed)
    d = case.data
    train = PeriodicData(d.u[:, :, :1], d.y[:, :, :1], d.fs, LINES)
    val = PeriodicData(d.u[:, :, 1:], d.y[:, :, 1:], d.fs, LINES)
    bla = robust_bla(d)
    u0, y0 = float(d.u.mean()), float(d.y.mean())
    linear = {n: fit_linear_ss(bla, nx=n).with_operating_point(u0, y0) for n in (1, 2, 3)}
    return train, val, linear


GRID = {
    "nx": (1, 2, 3),
    "degrees": ((2,), (2, 3)),
    "equations": ("state", "state+output"),
}


@pytest.fixture(scope="module")
def duffing_scan():
    train, val, linear = _split(k3=1.0, seed=1)
    return scan_pnlss(train, val, **GRID, max_iter=25, linear=linear, workers=1)


def test_scan_selects_the_duffing_structure(duffing_scan) -> None:
    """Truth: nx = 2, a cubic term in the state equation only (test_pnlss_duffing.duffing)."""
    best = duffing_scan.best_row
    assert best.equations == "state", duffing_scan.to_markdown()
    assert 3 in best.degrees, duffing_scan.to_markdown()
    assert best.nx == 2, duffing_scan.to_markdown()
    rows = duffing_scan.table
    assert len(rows) == 12 and sum(r["selected"] for r in rows) == 1
    quadratic = [r for r in duffing_scan.rows if r.degrees == (2,) and r.nx == 2]
    assert all(r.validation_error > 2 * best.validation_error for r in quadratic)
    y = duffing_scan.best.simulate(np.zeros(8) + 0.3)
    assert y.shape == (8,) and np.all(np.isfinite(y))


def test_scan_table_and_report_hold_every_candidate(duffing_scan) -> None:
    md, csv = duffing_scan.to_markdown(), duffing_scan.to_csv()
    assert md.count("\n| ") == 12 and "(selected)" in md and "one-standard-error" in md
    assert csv.count("\n") == 13 and csv.startswith("nx,degrees,equations")
    for row in duffing_scan.rows:
        assert row.status == "ok" and row.n_params > 0 and row.fit_seconds > 0


def test_scan_on_a_linear_system_keeps_the_smallest_model() -> None:
    train, val, linear = _split(k3=0.0, seed=2)
    result = scan_pnlss(
        train, val, nx=(1, 2), degrees=((2,), (2, 3)), equations=("state",), max_iter=10,
        linear=linear, workers=1,
    )  # fmt: skip
    sizes = [r.n_params for r in result.rows if r.nx == result.best_row.nx]
    assert result.best_row.n_params == min(sizes)
    assert result.best_row.degrees == (2,)


def test_one_standard_error_rule() -> None:
    def row(n: int, err: float, se: float, status: str = "ok") -> ScanRow:
        return ScanRow(1, (2,), "state", "full", n, err, se, err, 0.1, status)

    # The richest model is best, but the small one is within one SE of it.
    assert select_one_se([row(10, 0.105, 0.01), row(50, 0.1, 0.01)])[0] == 0
    # Beyond one SE: the richer model wins.
    assert select_one_se([row(10, 0.2, 0.01), row(50, 0.1, 0.01)])[0] == 1
    # Failed candidates are never selected; all failed: a clear error.
    assert select_one_se([row(5, float("nan"), 0, "failed: x"), row(9, 0.3, 0.01)])[0] == 1
    with pytest.raises(ValueError, match="no PNLSS candidate could be fitted"):
        select_one_se([row(5, float("nan"), 0, "failed: diverged")])


def _row(n: int, err: float, se: float, status: str = "ok") -> ScanRow:
    return ScanRow(1, (2,), "state", "full", n, err, se, err, 0.1, status)


def test_cross_fit_prefers_the_simpler_model_when_a_fit_depends_on_its_split() -> None:
    """Issue 22: the richer candidate wins on the first held-out realization by far more than
    its noise SE, but fitted with the other realization held out it is worse than the simple
    one. Its K-fold SE (the spread over the splits) then puts the simple one within reach."""
    simple = [_row(10, 0.30, 0.01), _row(10, 0.30, 0.01)]
    rich = [_row(50, 0.20, 0.01), _row(50, 0.36, 0.01)]
    assert select_one_se([simple[0], rich[0]])[0] == 1  # one split: the rich one
    rows = [cross_fit(simple), cross_fit(rich)]
    assert rows[1].validation_error == pytest.approx(0.28)
    assert rows[1].validation_se == pytest.approx(np.std([0.20, 0.36], ddof=1) / np.sqrt(2))
    assert rows[1].split_errors == (0.20, 0.36)
    # Splits that agree: the SE is the noise of the mean of K errors, never zero.
    assert rows[0].validation_se == pytest.approx(np.sqrt(2 * 0.01**2) / 2)
    assert select_one_se(rows)[0] == 0


def test_cross_fit_rejects_a_candidate_that_fails_on_another_split() -> None:
    row = cross_fit([_row(10, 0.2, 0.01), _row(10, 0.3, 0.01, "unstable at 1.3× the ...")])
    assert row.status == "split 2: unstable at 1.3× the ..." and np.isnan(row.validation_error)
    row = cross_fit([_row(10, 0.2, 0.01), _row(10, float("inf"), float("nan"))])
    assert row.status == "split 2: diverges on the validation data"
    assert cross_fit([_row(10, 0.2, 0.01)]).split_errors == ()  # one split: the row as it is


def test_scan_with_a_second_split_keeps_the_first_splits_models() -> None:
    """The swapped split (realization 0 held out) scores every candidate a second time; the
    models, and the first split's errors, are those of the one-split scan."""
    train, val, linear = _split(k3=1.0, seed=1)
    grid = {"nx": (2,), "degrees": ((2,), (3,)), "equations": ("state",), "max_iter": 8}
    one = scan_pnlss(train, val, **grid, linear=linear, workers=1)
    two = scan_pnlss(train, val, **grid, linear=linear, workers=1, splits=[(val, train)])
    for a, b, ma, mb in zip(one.rows, two.rows, one.models, two.models, strict=True):
        assert b.split_errors[0] == a.validation_error and len(b.split_errors) == 2
        assert b.validation_error == pytest.approx(np.mean(b.split_errors))
        assert ma is not None and mb is not None
        np.testing.assert_array_equal(ma.E, mb.E)
    assert " / " in two.to_markdown() and "split_errors" in two.to_csv()
    # A further split's fit gives its row only: its model is not shipped back from a worker.
    c = candidate_grid(nx=(2,), degrees=((2,),), equations=("state",))[0]
    options = {"max_iter": 8, "stress": 1.3, "keep_model": False}
    row, model = fit_candidate(c, linear[2], val, train, options)
    assert model is None and row.status == "ok"
    assert row.validation_error == two.rows[0].split_errors[1]
    two_records = PeriodicData(np.concatenate([val.u, val.u], 2), np.concatenate([val.y, val.y], 2),
                               val.fs, LINES)  # fmt: skip
    with pytest.raises(ValueError, match="split 2: its sets must match"):
        scan_pnlss(train, val, **grid, linear=linear, workers=1, splits=[(train, two_records)])


def test_grid_is_checked() -> None:
    assert len(candidate_grid()) == 3 * 3 * 2
    with pytest.raises(ValueError, match="unknown equations"):
        candidate_grid(equations=("output",))
    with pytest.raises(ValueError, match="state orders"):
        candidate_grid(nx=(0,))
    with pytest.raises(ValueError, match="unknown start"):
        candidate_grid(starts=("random",))
    both = candidate_grid(nx=(1,), degrees=((2,),), equations=("state",),
                          starts=("linear", "output_ls"))  # fmt: skip
    assert [c.start for c in both] == ["linear", "output_ls"]


@pytest.mark.slow  # starts a local Dask cluster (worker processes)
def test_dask_cluster_selects_the_same_model_as_the_serial_scan() -> None:
    from dask.distributed import Client, LocalCluster

    train, val, linear = _split(k3=1.0, seed=1)
    grid = {"nx": (2,), "degrees": ((2,), (2, 3)), "equations": ("state", "state+output")}
    splits = [(val, train)]  # each task gets its own split's data
    serial = scan_pnlss(train, val, **grid, max_iter=10, linear=linear, workers=1, splits=splits)
    with (
        LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        remote = scan_pnlss(
            train, val, **grid, max_iter=10, linear=linear, client=client, splits=splits
        )
    assert remote.best_index == serial.best_index
    for a, b in zip(remote.rows, serial.rows, strict=True):
        assert a.validation_error == pytest.approx(b.validation_error, rel=1e-9)
        assert a.split_errors == pytest.approx(b.split_errors, rel=1e-9)
    np.testing.assert_allclose(remote.best.E, serial.best.E, rtol=1e-9, atol=1e-12)
    assert N == 1024 and P == 3  # the shared case's layout, as _split assumes


GUARDLESS_SCRIPT = """
import sys
sys.path.insert(0, {test_dir!r})
from test_pnlss_duffing import LINES, make_case
from aero_identification import scan_pnlss
from aero_identification.periodic_data import PeriodicData

d = make_case(k3=1.0, seed=1).data
train = PeriodicData(d.u[:, :, :1], d.y[:, :, :1], d.fs, LINES)
val = PeriodicData(d.u[:, :, 1:], d.y[:, :, 1:], d.fs, LINES)
scan = scan_pnlss(train, val, nx=(2,), degrees=((2,), (3,)), equations=("state",), max_iter=3,
                  workers=2)
print("WORKERS", scan.workers)
print("SELECTED", scan.best_row.degrees)
"""


@pytest.mark.slow  # starts a local Dask cluster (worker processes)
def test_scan_runs_from_a_script_without_a_main_guard(tmp_path: Path) -> None:
    """Issue 22: the local workers must not re-run the caller's script (spawn re-imports
    __main__; an unguarded script then failed with "Nanny failed to start")."""
    import subprocess

    script = tmp_path / "plain_scan.py"
    script.write_text(GUARDLESS_SCRIPT.format(test_dir=str(Path(__file__).parent)))
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "WORKERS local Dask cluster, 2 worker processes" in done.stdout, done.stdout
    assert "SELECTED" in done.stdout and "bootstrapping" not in done.stderr
    assert "__main__" not in done.stderr or "Traceback" not in done.stderr
