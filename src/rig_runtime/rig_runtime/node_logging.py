"""A node's Python logger, whose records go to the node's rcl logger: the console in rcutils'
format and /rosout (the node modules write printf-style, as Python's logging does)."""

import logging
from typing import Any

__all__ = ["RosoutHandler", "make_logger"]


class RosoutHandler(logging.Handler):
    """Python log records -> the node's rcl logger (console and /rosout)."""

    def __init__(self, rcl_logger: Any) -> None:
        super().__init__()
        self.rcl_logger = rcl_logger

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            level = record.levelno
            if level >= logging.CRITICAL:
                self.rcl_logger.fatal(text)
            elif level >= logging.ERROR:
                self.rcl_logger.error(text)
            elif level >= logging.WARNING:
                self.rcl_logger.warning(text)
            elif level >= logging.INFO:
                self.rcl_logger.info(text)
            else:
                self.rcl_logger.debug(text)
        except Exception:
            self.handleError(record)


def make_logger(fq_name: str, level: int | str) -> logging.Logger:
    """The node's Python logger (printf-style, as the node modules write); its records go to
    the node's rcl logger: the console in rcutils' format and /rosout."""
    logger = logging.getLogger(f"rig{fq_name.replace('/', '.')}")
    for old in list(logger.handlers):  # a node of the same name made before in this process
        logger.removeHandler(old)
    logger.propagate = False
    logger.setLevel(level)
    return logger
