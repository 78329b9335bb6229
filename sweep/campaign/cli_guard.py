"""What every ``dchfrac campaign`` command shares: its usage error, the guard that turns a bad spec or argument into
one line on stderr and an exit code, and the warning naming a campaign's damaged runs.

Exit codes: 2 for a bad spec or argument, 1 for damaged runs or a table that would get emptier.
"""
from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["UsageError", "guarded", "name_damaged"]


class UsageError(ValueError):
    """A bad argument (e.g. an unwritable --results): one line on stderr, exit code 2."""


def guarded(fn):
    """Bad spec or arguments -> message on stderr and exit code 2 (no traceback)."""
    import functools

    @functools.wraps(fn)
    def wrapper(args) -> int:
        from sweep.campaign.plan import DamagedRunsError, EmptierResultError
        from sweep.campaign.spec import SpecError

        try:
            return fn(args)
        except (SpecError, UsageError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        except ValueError as e:
            if getattr(args, "campaign_command", None) == "run" and "must be" in str(e):
                print(f"error: {e}", file=sys.stderr)
                return 2
            raise
        except (DamagedRunsError, EmptierResultError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        except RuntimeError as e:
            if "is in use by process" in str(e):
                print(f"error: {e}", file=sys.stderr)
                return 2
            raise

    return wrapper


def name_damaged(source, results) -> None:
    """A warning on stderr naming the damaged runs of the campaign ``source`` (spec TOML, or campaign folder
    holding its spec.toml), as ``status`` names them; nothing when the spec is not at hand."""
    from sweep.campaign.plan import plan_campaign
    from sweep.campaign.spec import load_spec

    p = Path(source)
    folder = p.is_dir()
    spec_file = p / "spec.toml" if folder else p
    if not spec_file.is_file():
        return
    plan = plan_campaign(load_spec(spec_file), p.parent if folder else results)
    if plan.damaged:
        print(f"warning: campaign {plan.spec.name}: {len(plan.damaged)} damaged run(s) (files missing, changed or "
              f"unreadable since their record was written), left out; `dchfrac campaign run` reruns them:\n"
              + plan.damage_text(), file=sys.stderr)
