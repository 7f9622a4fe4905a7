"""Pressure-tap layout: chordwise tap positions, read from config/taps.yaml.

One source of truth for the simulated wing, the scanner channel order and the lift integration.
Tap order is scanner channel order: the leading-edge tap first, then the upper surface from the
leading edge to the trailing edge, then the lower surface likewise.
"""

import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from pressure_scanner.naca_section import NACA0018_THICKNESS, contour_parameter, half_thickness

SURFACE_SIDE = {"leading_edge": 0, "upper": 1, "lower": -1}
_PACKAGE = "pressure_scanner"
# A tap further than this from the section contour is a typo in the file, not a real position.
_CONTOUR_TOLERANCE = 2e-4


@dataclass(frozen=True)
class TapLayout:
    """Chordwise tap positions of one tap row.

    names: (n,) tap names; surface: (n,) "leading_edge" | "upper" | "lower".
    x_c, z_c: (n,) position in chords (x from the leading edge, z positive on the upper side).
    side: (n,) +1 upper, -1 lower, 0 leading edge.
    row_span_fraction: spanwise station of the row as a fraction of the (semi-)span.
    thickness_ratio: t/c of the NACA 00xx section the taps sit on.
    """

    names: tuple[str, ...]
    surface: tuple[str, ...]
    x_c: np.ndarray
    z_c: np.ndarray
    side: np.ndarray
    row_span_fraction: float = 0.5
    thickness_ratio: float = NACA0018_THICKNESS

    def __post_init__(self) -> None:
        _validate_layout(self)

    @property
    def n_taps(self) -> int:
        return len(self.names)

    @property
    def phi(self) -> np.ndarray:
        """(n,) contour parameter φ of each tap (naca_section.py)."""
        return contour_parameter(self.x_c, self.side)

    @property
    def upper(self) -> np.ndarray:
        """Indices of the upper-surface taps, leading edge to trailing edge."""
        return np.flatnonzero(self.side == 1)

    @property
    def lower(self) -> np.ndarray:
        """Indices of the lower-surface taps, leading edge to trailing edge."""
        return np.flatnonzero(self.side == -1)

    @property
    def leading_edge(self) -> int:
        return int(np.flatnonzero(self.side == 0)[0])

    def xyz_m(self, chord_m: float, span_m: float) -> np.ndarray:
        """(n, 3) tap positions in metres in the wing frame: x along the chord from the
        leading edge, y spanwise from the root, z normal to the chord (up on the upper side)."""
        xyz = np.empty((self.n_taps, 3))
        xyz[:, 0] = self.x_c * chord_m
        xyz[:, 1] = self.row_span_fraction * span_m
        xyz[:, 2] = self.z_c * chord_m
        return xyz


def _validate_layout(layout: TapLayout) -> None:
    n = len(layout.names)
    for label, arr in (("x_c", layout.x_c), ("z_c", layout.z_c), ("side", layout.side)):
        if np.shape(arr) != (n,):
            raise ValueError(f"tap layout: {label} has shape {np.shape(arr)}, expected ({n},)")
    if len(layout.surface) != n:
        raise ValueError("tap layout: one surface label per tap is needed")
    if n < 7:
        raise ValueError(f"tap layout: {n} taps cannot resolve a pressure distribution (>= 7)")
    if len(set(layout.names)) != n:
        raise ValueError("tap layout: tap names must be unique")
    if np.count_nonzero(layout.side == 0) != 1:
        raise ValueError("tap layout: exactly one tap must have surface 'leading_edge'")
    le = int(np.flatnonzero(layout.side == 0)[0])
    if le != 0:
        raise ValueError("tap layout: the leading-edge tap must be the first tap (channel 0)")
    if layout.x_c[le] != 0.0 or layout.z_c[le] != 0.0:
        raise ValueError("tap layout: the leading-edge tap must sit at x/c = 0, z/c = 0")
    if not (0.0 < layout.row_span_fraction < 1.0):
        raise ValueError("tap layout: row_span_fraction must lie in (0, 1)")
    for side, label in ((1, "upper"), (-1, "lower")):
        idx = np.flatnonzero(layout.side == side)
        if idx.size < 3:
            raise ValueError(f"tap layout: the {label} surface needs >= 3 taps, has {idx.size}")
        x = layout.x_c[idx]
        if np.any(np.diff(idx) != 1) or np.any(np.diff(x) <= 0.0):
            raise ValueError(
                f"tap layout: list the {label}-surface taps contiguously from the leading edge "
                "to the trailing edge (x/c strictly increasing)"
            )
        if x[0] <= 0.0 or x[-1] >= 1.0:
            raise ValueError(f"tap layout: {label}-surface taps must lie in 0 < x/c < 1")
        expected = side * half_thickness(x, layout.thickness_ratio)
        worst = np.max(np.abs(layout.z_c[idx] - expected))
        if worst > _CONTOUR_TOLERANCE:
            k = idx[int(np.argmax(np.abs(layout.z_c[idx] - expected)))]
            raise ValueError(
                f"tap layout: tap {layout.names[k]} (z/c = {layout.z_c[k]:.5f}) is "
                f"{worst:.2e} chords off the NACA 00{round(100 * layout.thickness_ratio):02d} "
                f"{label} surface; fix its z_c (or the thickness_ratio)"
            )


def cosine_clustered_taps(
    n_per_surface: int = 24,
    x_last: float = 0.95,
    thickness_ratio: float = NACA0018_THICKNESS,
    row_span_fraction: float = 0.5,
) -> TapLayout:
    """Leading-edge tap plus n_per_surface taps per surface at equal steps of the contour
    parameter φ up to x/c = x_last (x/c = (1 - cos φ)/2: dense at both edges)."""
    phi_last = math.acos(1.0 - 2.0 * x_last)
    phi = np.arange(1, n_per_surface + 1) / n_per_surface * phi_last
    x = 0.5 * (1.0 - np.cos(phi))
    z = half_thickness(x, thickness_ratio)
    names = ["LE"] + [f"U{i:02d}" for i in range(1, n_per_surface + 1)]
    names += [f"L{i:02d}" for i in range(1, n_per_surface + 1)]
    surface = ("leading_edge",) + ("upper",) * n_per_surface + ("lower",) * n_per_surface
    return TapLayout(
        names=tuple(names),
        surface=surface,
        x_c=np.concatenate([[0.0], x, x]),
        z_c=np.concatenate([[0.0], z, -z]),
        side=np.array([SURFACE_SIDE[s] for s in surface], dtype=np.int8),
        row_span_fraction=row_span_fraction,
        thickness_ratio=thickness_ratio,
    )


def default_taps_path() -> Path:
    """config/taps.yaml of this package: source tree, ament share directory or sys.prefix."""
    candidates = [Path(__file__).resolve().parents[1] / "config" / "taps.yaml"]
    try:  # installed by colcon: <prefix>/share/pressure_scanner/config/taps.yaml
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory(_PACKAGE)) / "config" / "taps.yaml")
    except Exception:  # ament_index is absent off ROS machines, or the package is not indexed
        pass
    prefixes = [sys.prefix, *os.environ.get("COLCON_PREFIX_PATH", "").split(os.pathsep)]
    for prefix in prefixes:
        if prefix:
            candidates.append(Path(prefix) / "share" / _PACKAGE / "config" / "taps.yaml")
    for path in candidates:
        if path.is_file():
            return path
    searched = ", ".join(str(p) for p in candidates)
    raise FileNotFoundError(f"taps.yaml not found (searched {searched}); pass path= explicitly")


def load_taps(path: str | Path | None = None) -> TapLayout:
    """Read a tap layout from YAML (default: this package's config/taps.yaml).

    The file holds `thickness_ratio`, `row_span_fraction` and a list `taps` of
    {name, surface, x_c, z_c} in scanner channel order (see config/taps.yaml).
    """
    file = Path(path) if path is not None else default_taps_path()
    try:
        doc = yaml.safe_load(file.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"cannot read tap layout {file}: {exc}") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("taps"), list):
        raise ValueError(f"{file}: expected a mapping with a list 'taps'")
    names, surface, x_c, z_c = [], [], [], []
    for k, entry in enumerate(doc["taps"]):
        try:
            names.append(str(entry["name"]))
            label = str(entry["surface"])
            x_c.append(float(entry["x_c"]))
            z_c.append(float(entry["z_c"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{file}: tap #{k} needs name, surface, x_c, z_c ({exc})") from exc
        if label not in SURFACE_SIDE:
            raise ValueError(
                f"{file}: tap {names[-1]} has surface {label!r}; use one of {list(SURFACE_SIDE)}"
            )
        surface.append(label)
    try:
        return TapLayout(
            names=tuple(names),
            surface=tuple(surface),
            x_c=np.array(x_c),
            z_c=np.array(z_c),
            side=np.array([SURFACE_SIDE[s] for s in surface], dtype=np.int8),
            row_span_fraction=float(doc.get("row_span_fraction", 0.5)),
            thickness_ratio=float(doc.get("thickness_ratio", NACA0018_THICKNESS)),
        )
    except ValueError as exc:
        raise ValueError(f"{file}: {exc}") from exc
