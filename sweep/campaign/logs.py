"""Logging of the ``dchfrac`` command line: ``-v`` / ``-q`` set the level of the ``dchfrac`` loggers.

Progress and information go through ``logging`` (loggers ``dchfrac.*``, on stderr); results a user
asked for (tables, verdicts, paths written) go to stdout. Levels: default INFO, ``-v`` DEBUG,
``-q`` WARNING, ``-qq`` ERROR.
"""
from __future__ import annotations

import logging
import sys

__all__ = ["LOGGER", "setup_logging", "end_logging", "level_of", "LogStream"]

LOGGER = "dchfrac"


def level_of(verbose: int = 0, quiet: int = 0) -> int:
    """The logging level of ``-v`` x verbose and ``-q`` x quiet (INFO when neither)."""
    n = int(verbose) - int(quiet)
    return {1: logging.DEBUG, 0: logging.INFO, -1: logging.WARNING}.get(n, logging.DEBUG if n > 1 else logging.ERROR)


def setup_logging(verbose: int = 0, quiet: int = 0, stream=None) -> logging.Handler:
    """Send the ``dchfrac`` loggers to ``stream`` (default: the current stderr) at the level of ``-v`` / ``-q``.

    Idempotent (replaces the handler an earlier call added); returns the handler for :func:`end_logging`."""
    lg = logging.getLogger(LOGGER)
    end_logging()
    h = logging.StreamHandler(stream) if stream is not None else _StderrHandler()
    h.setFormatter(logging.Formatter("%(asctime)s %(message)s", "%H:%M:%S"))
    h._dchfrac = True  # type: ignore[attr-defined]
    lg.addHandler(h)
    lg.setLevel(level_of(verbose, quiet))
    return h


def end_logging() -> None:
    """Remove the handler of :func:`setup_logging` and reset the level (a command leaves no global state)."""
    lg = logging.getLogger(LOGGER)
    for h in list(lg.handlers):
        if getattr(h, "_dchfrac", False):
            lg.removeHandler(h)
    lg.setLevel(logging.NOTSET)


class _StderrHandler(logging.StreamHandler):
    """A handler writing to whatever ``sys.stderr`` is when a record comes (never to a stale stream)."""

    def __init__(self):
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


class LogStream:
    """A text stream whose lines go to a logger at INFO (for APIs that take a progress stream)."""

    def __init__(self, logger: logging.Logger | str):
        self.logger = logging.getLogger(logger) if isinstance(logger, str) else logger

    def write(self, text: str) -> int:
        for line in str(text).splitlines():
            if line.strip():
                self.logger.info(line)
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False
