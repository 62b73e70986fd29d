"""A many-run job's worker processes are forked; garbage holding MuJoCo's thread pool (a batch's) that a
worker's collection reaches would wait there for pool threads the fork did not copy, and the job would hang for
good (seen: a validation's worker stuck in the pool's destructor under the full suite). The fan-out collects
the garbage before it forks and keeps what lives out of the workers' collections (``twin.app.fanout._local``)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import gc

    from mujoco import batch as mjbatch

    import twin.app.fanout as fanout
    from twin.plant import Plant

    class Holder:
        pass

    held = Holder()
    held.me = held  # a cycle: only the collector frees it
    held.batch = mjbatch.Batch(Plant().model, 4, nthread=2)
    held.batch.step()  # its pool's threads started
    del held

    def collect_in_worker(chunk):
        gc.collect()  # the worker's collection reaches what the parent left
        return [{"chunk": chunk}]

    fanout.run_chunk = collect_in_worker  # the forked workers run this (fork copies the module)
    print(sorted(lo for lo, _ in fanout._local([(0, 1), (1, 2)], 2)))
    """
)


@pytest.mark.quick
def test_forked_workers_never_collect_a_batchs_thread_pool() -> None:
    """Measured before the fix: the script hung (killed at its 30 s timeout); after: it ends in about 2 s."""
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[0, 1]"
