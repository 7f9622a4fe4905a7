"""Test support for test_scanner_udp_*.py: run the simulated scanner process with bounded waits.

Imported through the test directory on sys.path (pytest --import-mode=importlib); the module
name is unique in the repository on purpose.
"""

import json
import select
import subprocess
import sys
from pathlib import Path


def run_sim_scanner(args: list[str], stderr_path: Path, timeout_s: float) -> dict[str, int]:
    """Run ``python -m pressure_scanner.sim_scanner`` to completion (it needs --frames) and
    return its final JSON summary. Kills it if it has not finished within ``timeout_s``."""
    with open(stderr_path, "w") as stderr:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pressure_scanner.sim_scanner", *args],
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
        )
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
        first = proc.stdout.readline() if ready else ""
        if not first.strip().isdigit():
            raise RuntimeError(
                f"sim_scanner did not start (first line {first!r}); "
                f"stderr: {stderr_path.read_text()[-2000:]}"
            )
        try:
            out, _ = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"sim_scanner still running after {timeout_s} s") from None
        if proc.returncode != 0:
            raise RuntimeError(
                f"sim_scanner exited with {proc.returncode}: {stderr_path.read_text()[-2000:]}"
            )
        return json.loads(out.strip().splitlines()[-1])
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5.0)
        if proc.stdout is not None:
            proc.stdout.close()
