"""In CI (``CI=true``), a skipped ``ci_required`` test fails with its reason (conftest.py);
elsewhere it is an ordinary skip, shown with its reason (``-rs``)."""

from pathlib import Path

import pytest

SUITE = """
import pytest

@pytest.mark.ci_required
@pytest.mark.skipif(True, reason="the data are not here")
def test_needs_data():
    pass

@pytest.mark.skipif(True, reason="optional")
def test_optional():
    pass
"""


@pytest.mark.parametrize("ci", ["true", ""])
def test_a_required_test_that_skips_fails_in_ci(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, ci: str
) -> None:
    pytester.makeconftest((Path(__file__).parents[1] / "conftest.py").read_text())
    pytester.makepyfile(SUITE)
    monkeypatch.setenv("CI", ci)
    result = pytester.runpytest("-rs", "-p", "no:cacheprovider")
    if ci:
        result.assert_outcomes(errors=1, skipped=1)  # failed in its setup, where it skipped
        assert result.ret != 0
        result.stdout.fnmatch_lines(["*skipped in CI, where it must run: *the data are not here*"])
    else:
        result.assert_outcomes(skipped=2)
        result.stdout.fnmatch_lines(["SKIPPED*the data are not here*"])
