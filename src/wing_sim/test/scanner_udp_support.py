"""Test support for test_scanner_udp_*.py: run the simulated scanner process with bounded waits.

Imported through the test directory on sys.path (pytest --import-mode=importlib); the module
name is unique in the repository on purpose.
"""

import json
import subprocess
from pathlib import Path

from rig_testing.processes import start_port_printer


def run_sim_scanner(args: list[str], stderr_path: Path, timeout_s: float) -> dict[str, int]:
    """Run ``python -m wing_sim.sim_scanner`` to completion (it needs --frames) and
    return its final JSON summary. Kills it if it has not finished within ``timeout_s``."""
    proc, _ = start_port_printer("wing_sim.sim_scanner", args, stderr_path, timeout_s)
    try:
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
