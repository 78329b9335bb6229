"""Where a workflow run's cost goes: forward runs actually computed (not served from a cache) per stage,
coarse and fine models apart, and the stage's wall time in the progress log."""
from __future__ import annotations

import logging
import time

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["RunLedger"]


class RunLedger:
    """Forward runs per stage of the workflow; ``mark(stage)`` books the runs since the previous mark and
    logs them with the seconds spent.  ``stages``: {stage: {"coarse": runs, "fine": runs}}."""

    def __init__(self, forward, fine: list):
        self.models = {"coarse": [forward], "fine": list(fine)}
        self.last = self._now()
        self.stages: dict = {}
        self.t_last = time.perf_counter()

    def _now(self) -> dict:
        return {k: sum(int(getattr(m, "n_runs", 0)) for m in ms) for k, ms in self.models.items()}

    def mark(self, stage: str) -> None:
        now = self._now()
        row = self.stages.setdefault(stage, {k: 0 for k in now})
        for k in now:
            row[k] += now[k] - self.last[k]
        t = time.perf_counter()
        log.info("stage %s done: %d coarse + %d fine forward runs, %.0f s", stage,
                 now["coarse"] - self.last["coarse"], now["fine"] - self.last["fine"], t - self.t_last)
        self.last, self.t_last = now, t
