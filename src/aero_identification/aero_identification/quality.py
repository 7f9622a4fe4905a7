"""Data quality: the lines that say what the identification could not use, and why (the
account itself comes from the source adapter: campaign_source.data_quality, records).

Light (no numerical stack): the identifier node and the command line read these records too.
"""

from typing import Any


def data_quality_lines(quality: dict[str, Any]) -> list[str]:
    """One line per problem of a data-quality record (empty when clean)."""
    lines = []
    for name, c in quality.get("samples", {}).items():
        if c["missing"] or c["duplicated"]:
            lines.append(
                f"{name}: {c['missing']} of {c['expected']} plan samples missing, "
                f"{c['duplicated']} duplicated"
            )
    lines += [f"anomaly: {a}" for a in quality.get("anomalies", [])]
    lines += [f"excluded period: {p}" for p in quality.get("excluded_periods", [])]
    lines += [f"excluded sine record: {r}" for r in quality.get("excluded_sines", [])]
    return lines


def data_quality_note(quality: dict[str, Any]) -> str:
    """The warning put above a Table 1 built from data that were not all usable."""
    lines = data_quality_lines(quality)
    counts = (
        f"{len(quality.get('excluded_periods', []))} period(s) and "
        f"{len(quality.get('excluded_sines', []))} sine record(s) excluded, "
        f"{len(quality.get('anomalies', []))} anomaly record(s)"
    )
    shown = "\n".join(f"> - {line}" for line in lines[:20])
    more = f"\n> - … {len(lines) - 20} more (data_quality.md)" if len(lines) > 20 else ""
    head = f"> **Data not clean**: {counts}; the table below uses only what was left."
    return f"{head}\n{shown}{more}\n\n"
