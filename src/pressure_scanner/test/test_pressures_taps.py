"""Tap layout file: the shipped layout, wing-frame positions, and clear errors for bad files."""

from pathlib import Path

import numpy as np
import pytest

from pressure_scanner.naca_section import half_thickness
from pressure_scanner.taps import cosine_clustered_taps, load_taps


def test_shipped_layout_is_49_cosine_clustered_taps_on_the_naca0018() -> None:
    taps = load_taps()
    assert taps.n_taps == 49
    assert taps.leading_edge == 0 and taps.x_c[0] == 0.0
    assert taps.upper.size == 24 and taps.lower.size == 24
    # equal steps of the cosine-spacing angle, last tap at x/c = 0.95
    phi = np.arccos(1.0 - 2.0 * taps.x_c[taps.upper])
    np.testing.assert_allclose(np.diff(phi), phi[0], rtol=1e-3)  # 6 decimals in the file
    assert taps.x_c[taps.upper][-1] == pytest.approx(0.95, abs=1e-6)
    np.testing.assert_allclose(taps.x_c[taps.lower], taps.x_c[taps.upper])
    np.testing.assert_allclose(
        taps.z_c[taps.upper], half_thickness(taps.x_c[taps.upper]), atol=1e-6
    )
    np.testing.assert_allclose(taps.z_c[taps.lower], -taps.z_c[taps.upper])
    generated = cosine_clustered_taps()
    np.testing.assert_allclose(taps.x_c, generated.x_c, atol=1e-6)


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "taps.yaml"
    path.write_text(body)
    return path


def _layout_text(edit: dict[int, str] | None = None) -> str:
    taps = cosine_clustered_taps(n_per_surface=4)
    lines = ["thickness_ratio: 0.18", "taps:"]
    rows = zip(taps.names, taps.surface, taps.x_c, taps.z_c, strict=True)
    for k, (name, surface, x, z) in enumerate(rows):
        line = f"  - {{name: {name}, surface: {surface}, x_c: {x:.8f}, z_c: {z:.8f}}}"
        lines.append((edit or {}).get(k, line))
    return "\n".join(lines) + "\n"


def test_a_valid_small_layout_loads(tmp_path: Path) -> None:
    taps = load_taps(_write(tmp_path, _layout_text()))
    assert taps.n_taps == 9


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({2: "  - {name: U02, surface: top, x_c: 0.5, z_c: 0.1}"}, "surface 'top'"),
        ({2: "  - {name: U02, surface: upper, x_c: 0.5}"}, "needs name, surface, x_c, z_c"),
        ({2: "  - {name: U02, surface: upper, x_c: 0.30, z_c: 0.02}"}, "off the NACA 0018"),
        ({2: "  - {name: U02, surface: upper, x_c: 0.001, z_c: 0.00939}"}, "strictly increasing"),
    ],
)
def test_bad_layout_files_are_refused_with_a_clear_message(
    tmp_path: Path, edit: dict[int, str], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        load_taps(_write(tmp_path, _layout_text(edit)))


def test_missing_file_names_the_path(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"nope\.yaml"):
        load_taps(tmp_path / "nope.yaml")
