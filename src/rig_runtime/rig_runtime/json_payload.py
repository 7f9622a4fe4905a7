"""The JSON object a message carries: a typed message's JSON payload field (the plan's
``plan_json``, the model's ``model_json``), or the ``data`` of the std_msgs/String that bags
recorded before the rig's own messages carried on the same topic. Standard library only: the
offline readers and the identification use it without a middleware."""

import json
from typing import Any

__all__ = ["json_object"]


def json_object(msg: Any, field: str, topic: str) -> dict[str, Any]:
    """The object in ``msg.<field>``, or in ``msg.data`` (an old String), or ``msg`` itself when
    it is the JSON text; ValueError naming ``topic`` when there is none."""
    text = msg if isinstance(msg, str) else getattr(msg, field, getattr(msg, "data", None))
    if not isinstance(text, str):
        raise ValueError(f"{topic}: not a message with a JSON payload ({type(msg).__name__})")
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{topic} is not valid JSON: {error}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{topic}: not a JSON object")
    return value
