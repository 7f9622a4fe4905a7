"""Table 1's bootstrap with the structure scan rerun in every replicate (config.bootstrap_scan,
bootstrap.estimation_bootstrap): the selection's scatter enters the spread."""

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from aero_identification import pnlss_training
from aero_identification.dataset import Dataset, LevelRecord, SineData
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.periodic_data import PeriodicData, random_phase_period
from aero_identification.pipeline import identify

N, P, M = 256, 4, 3
LINES = np.arange(1, 40, 2)


def _steady(u: np.ndarray) -> np.ndarray:
    """x' = 0.8 x + 0.2 u, y = x + 0.05 x², in periodic steady state (the last of three)."""
    x, xs = 0.0, np.empty(u.size)
    for _ in range(3):
        for t in range(u.size):
            xs[t] = x
            x = 0.8 * x + 0.2 * u[t]
    return xs + 0.05 * xs**2


def _dataset() -> Dataset:
    """Two levels of odd random-phase multisines (N 256, 4 periods, 3 realizations) and a
    sine at each level's offset, all with output noise."""
    rng = np.random.default_rng(11)
    levels, sines = [], []
    for k, offset in enumerate((2.0, 6.0)):
        u, y = np.empty((N, P, M)), np.empty((N, P, M))
        for r in range(M):
            period = offset + random_phase_period(rng, N, LINES) / 0.1
            u[:, :, r] = period[:, None]
            y[:, :, r] = _steady(period)[:, None] + 0.02 * rng.standard_normal((N, P))
        levels.append(LevelRecord(str(k + 1), PeriodicData(u, y, 10.0, LINES), offset_deg=offset))
        t = np.arange(N) / 10.0
        sine = offset + 2.0 * np.sin(2 * np.pi * 0.3125 * t)  # 8 cycles per N samples
        out = _steady(sine) + 0.02 * rng.standard_normal(N)
        sines.append(SineData(f"sine {k}", 0.3125, offset, N // 8, sine, out))
    return Dataset(fs=10.0, levels=levels, sines=sines, sines_planned=True)


CONFIG = IdentificationConfig(
    nx=1, max_iter=5, clustering=False, clustering_ablation=False, bootstrap=3,
    bootstrap_scan=True, scan_nx=(1,), scan_degrees=((2,), (2, 3)), scan_equations=("state",),
    scan_max_iter=5, scan_workers=1, scan_stress=0.0,
)  # fmt: skip


def _spy(monkeypatch: Any) -> list[np.ndarray]:
    """Record the training outputs every structure scan gets."""
    seen: list[np.ndarray] = []
    real = pnlss_training.scan_pnlss

    def spy(data: PeriodicData, *args: Any, **kwargs: Any) -> Any:
        seen.append(data.y.copy())
        return real(data, *args, **kwargs)

    monkeypatch.setattr(pnlss_training, "scan_pnlss", spy)
    return seen


def test_every_replicate_runs_its_own_scan_and_says_what_it_kept(
    monkeypatch: Any, tmp_path: Path
) -> None:
    from aero_identification.report import write_report

    seen = _spy(monkeypatch)
    said: list[str] = []
    result = identify(_dataset(), CONFIG, final=True, log=said.append)
    boot = result.bootstrap
    assert result.scan is not None and boot is not None
    # One scan for the estimate, one per replicate, each on its own resampled periods.
    assert len(seen) == 1 + 3
    for replicate in seen[1:]:
        assert replicate.shape == seen[0].shape and not np.array_equal(replicate, seen[0])
    labels = {row.structure_label for row in result.scan.rows}
    assert boot.kept_structure == result.scan.best_row.structure_label
    assert len(boot.replicate_structures) == 3 and set(boot.replicate_structures) <= labels
    assert boot.same_structure == boot.replicate_structures.count(boot.kept_structure)
    assert all(math.isfinite(s) for s in boot.spreads_all.values()) and boot.spreads_all
    line = next(m for m in said if m.startswith("Table 1 estimation bootstrap"))
    assert f"3 structure scans (the estimate's structure kept in {boot.same_structure})" in line
    write_report(result, tmp_path)
    md = (tmp_path / "table1_all_levels.md").read_text()
    assert (
        f"each with its own structure scan (the estimate's structure, {boot.kept_structure}" in md
    )
    payload = json.loads((tmp_path / "models.json").read_text())["errors"]
    assert payload["bootstrap_structures"] == {
        "estimate": boot.kept_structure,
        "replicates": boot.replicate_structures,
    }


def test_without_it_the_replicates_refit_the_kept_structure(monkeypatch: Any) -> None:
    """The default: one scan (the estimate's); the replicates refit its kept structure, and
    nothing about the replicates' structures is reported."""
    seen = _spy(monkeypatch)
    result = identify(_dataset(), dataclasses.replace(CONFIG, bootstrap_scan=False), final=True)
    assert len(seen) == 1
    assert result.bootstrap is not None and not result.bootstrap.rescanned
    assert "structure scan" not in result.bootstrap.note(result.errors_all)


def test_without_a_scan_it_says_so_and_refits_the_one_structure(monkeypatch: Any) -> None:
    seen = _spy(monkeypatch)
    result = identify(_dataset(), dataclasses.replace(CONFIG, scan=False), final=True)
    assert not seen and result.bootstrap is not None and not result.bootstrap.rescanned
    assert any(w.startswith("bootstrap_scan: the all-levels PNLSS was not chosen") for w in
               result.warnings)  # fmt: skip
