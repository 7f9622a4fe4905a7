"""The identifier node's refit jobs, run in its worker process (or inline when debugging).

The worker keeps the latest :class:`~aero_identification.pipeline.IdentificationResult`
itself: the next job reuses its models (validation-only refits after sine tests) and its
level-1 PNLSS (while the level-1 data are unchanged), and the node receives only what it
publishes — the model payload (plain JSON data) and a short summary for its status. So the
node process never imports the numerical stack (scipy, scikit-learn, numba, matplotlib) and
never holds models; its memory is its intake buffers.

This module imports the pipeline only inside the jobs, so importing it is cheap.
"""

import ctypes
import gc
import math
import time
from pathlib import Path
from typing import Any

from .hyperparameters import IdentificationConfig
from .period_assembly import CampaignAssembler

_kept: dict[str, Any] = {}  # "last": the latest IdentificationResult of this process


def release_memory() -> None:
    """Collect garbage and hand freed heap back to the OS (glibc keeps it otherwise).

    A refit allocates and frees hundreds of MB; without the trim the resident size ratchets up
    from refit to refit although nothing is kept.
    """
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: nothing to trim
        pass


def status_mb(field: str) -> float:
    """A /proc/self/status memory figure (VmRSS, VmHWM) in MB; NaN where there is none."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


def _reset_peak_rss() -> None:
    """Restart VmHWM (the peak resident size) from the current size (Linux clear_refs 5)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def exit_with_parent(poll_s: float = 0.5) -> None:
    """Worker initializer: leave when the identifier node is gone, even if it was killed with
    SIGKILL (a ProcessPoolExecutor worker would otherwise wait on its queue forever, holding
    hundreds of MB). A terminal's Ctrl-C (SIGINT to the whole process group, as under
    ``ros2 launch``) is the node's to handle: the worker ignores it, and leaves when the node
    shuts its pool down or is gone, instead of dying with a KeyboardInterrupt traceback."""
    import os
    import signal
    import threading

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(0)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def warm_up() -> float:
    """Load the pipeline and its compiled kernels (see warm_up.warm_up); returns seconds."""
    from .warm_up import warm_up as pipeline_warm_up

    return pipeline_warm_up()


def refit(
    assembler: CampaignAssembler,
    config: IdentificationConfig,
    final: bool,
    out_dir: str,
    reuse_models: bool,
    final_models: bool = False,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """One refit: identify (only validate with the kept models if ``reuse_models``) and, when
    final, write the report to ``out_dir``.

    Args:
        reuse_models: only sine records completed since the last job: the multisine data, hence
            the models, are unchanged (a new worker without kept models fits them afresh, which
            gives the same models).
        final_models: every multisine period of the plan is in: fit the final identification's
            models now (pipeline.identify's ``final_models``), so that the final job only
            validates them.

    Returns:
        (payload, summary): the /identification/model payload (pipeline's ``to_json_dict``)
        and {complete, warnings, levels: [{name, clusters: [k, sizes] | None, excluded}],
        written (report files), data_quality (campaign_source.data_quality), timings_s,
        worker: {cpu_s, start_mb, peak_mb}}.
    """
    from .campaign_source import campaign_dataset
    from .pipeline import identify
    from .report import write_report

    cpu0 = time.process_time()
    release_memory()  # what the previous job freed
    _reset_peak_rss()
    start_mb = status_mb("VmRSS")
    last = _kept.get("last")
    dataset = campaign_dataset(assembler, final, config.min_periods)
    result = identify(
        dataset,
        config,
        final=final,
        models_from=last if reuse_models else None,
        previous=last,
        final_models=final_models,
    )
    _kept["last"] = result
    written: list[str] = []
    if out_dir and final:
        t0 = time.perf_counter()
        written = [str(p) for p in write_report(result, out_dir).values()]
        result.timings_s["report"] = time.perf_counter() - t0
    summary = {
        "complete": result.complete,
        "warnings": list(result.warnings),
        "levels": [
            {
                "name": lv.name,
                "clusters": None
                if lv.clusters is None
                else [int(lv.clusters.k), [int(s) for s in lv.clusters.sizes]],
                "excluded": list(lv.excluded),
            }
            for lv in result.levels.values()
        ],
        "written": written,
        "data_quality": result.data_quality,
        "timings_s": dict(result.timings_s),
        "worker": {
            "cpu_s": time.process_time() - cpu0,
            "start_mb": start_mb,
            "peak_mb": status_mb("VmHWM"),
        },
    }
    return result.to_json_dict(), summary
