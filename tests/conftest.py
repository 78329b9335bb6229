"""Suite-wide settings: one MKL/OpenMP thread per pytest-xdist worker when several workers share the cores.

The README's test command runs two workers on a 2-core machine.  MKL (PARDISO) starts one OpenMP thread per core
in every worker, so two busy-waiting pools would share two cores and each worker's factorizations would wait on
the other's spinning threads.  A campaign does the same for its parallel runs
(``sweep.campaign.scheduler.child_env``).  The variables are set before any test module loads MKL (``solver``
loads PARDISO on first use), and subprocesses started by tests (the CLI checks) inherit them.  numpy's OpenBLAS
pool keeps its default: a run holds it to one thread itself (``solver.simulate.one_openblas_thread``, checked in
test_threads.py).  A single-process session (``-n 0``) keeps the libraries' defaults.
"""
import os

import pytest


def _workers() -> int:
    try:
        return int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    except ValueError:
        return 1


if os.environ.get("PYTEST_XDIST_WORKER") and _workers() > 1:
    for _var in ("MKL_NUM_THREADS", "OMP_NUM_THREADS"):
        os.environ.setdefault(_var, "1")


@pytest.fixture
def table_folder(tmp_path):
    """A function writing a DataFrame as ``tmp_path/<name>/table.csv``: a campaign folder as `dchfrac judge`
    reads it; returns the folder."""
    def write(name, df):
        d = tmp_path / name
        d.mkdir()
        df.to_csv(d / "table.csv", index=False)
        return d

    return write
