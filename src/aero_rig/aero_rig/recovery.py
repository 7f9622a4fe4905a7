"""The final identification recovered from a campaign's bag, when the identifier's fell short.

``aero-rig campaign`` decides when (cli/campaign.py): the identifier stalled, died in its final
identification, or finished without plan samples the recorder may hold. The recovery is the
offline fit (offline.py) on the run's bag with the identifier's own parameters, its report
written into the run directory. (Repairing a damaged bag file is ``aero-rig bag recover``.)

Imports the offline fit only when a recovery runs, so that a campaign that needs none never
loads the numerical stack.
"""

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aero_identification.hyperparameters import IdentificationConfig
from rig_runtime.launcher import Launcher

from .verdict import bag_problems

Say = Callable[[str], None]  # one line for the user (the CLI prefixes and prints it)


def recover_from_bag(
    run_dir: Path, launcher: Launcher, reason: str, say: Say
) -> dict[str, Any] | None:
    """The final identification from the bag after ``reason`` (the identifier stalled, or its
    own identification fell short): the same pipeline on the same assembler (offline.py) with
    the identifier's own parameters (:func:`identifier_config`). What was recovered (for
    campaign.json), or None (and the reason stands) when the bag cannot be read."""
    from .offline import BagError, fit_bag

    bag = run_dir / "bag"
    say(reason)
    say(f"recovering the final identification from {bag}")
    try:
        config = identifier_config(launcher)
        result, data = fit_bag(bag, run_dir, config)
    except (BagError, ValueError, OSError) as exc:
        say(f"recovery from the bag failed: {exc}")
        return None
    for warning in data.warnings:
        say(f"warning: {warning}")
    return {
        "reason": reason,
        "from": str(bag),
        "samples_read": data.messages,
        "clean": result.clean,
    }


def recover_from_whole_bag(
    run_dir: Path, launcher: Launcher, total: int, reason: str, say: Say
) -> dict[str, Any] | None:
    """:func:`recover_from_bag` unless the bag is short of the plan's ``total`` samples itself
    (0: the plan was never seen): a second fit would only repeat the loss (said, and None)."""
    short = bag_problems(run_dir / "bag", total) if total else ["no plan seen"]
    if short:
        say(f"{reason}; the bag lacks samples too ({short[0]}): no recovery")
        return None
    return recover_from_bag(run_dir, launcher, reason, say)


def samples_missed(run_dir: Path) -> str | None:
    """What the identifier's final report lacks that a bag may hold: plan samples missing on a
    channel (None when none are, or there is no report)."""
    models = run_dir / "models.json"
    if not models.exists():
        return None
    samples = json.loads(models.read_text()).get("data_quality", {}).get("samples", {})
    missing = {name: int(c.get("missing", 0)) for name, c in samples.items()}
    if not any(missing.values()):
        return None
    counts = ", ".join(f"{n} {name}" for name, n in missing.items() if n)
    return f"the identifier's final identification missed plan samples ({counts})"


def identifier_config(launcher: Launcher) -> IdentificationConfig:
    """The identifier's hyperparameters as the graph started it: its declared defaults, its
    parameter files, the graph's and the campaign's overrides (rig_runtime.params), read by
    the function the node reads its own with (identifier_settings.py)."""
    from aero_identification.identifier_settings import PARAMETERS, identifier_settings
    from rig_runtime.params import assign, resolve_parameters

    spec = launcher.graph.node("identifier")
    params = resolve_parameters(PARAMETERS, spec.fq_name, spec.parameters)
    for source, values in (
        ("the graph", spec.parameter_overrides),
        ("the campaign", launcher.overrides.get("identifier", {})),
    ):
        for name, value in values.items():
            assign(params, name, value, source)
    return identifier_settings(params.as_dict()).config
