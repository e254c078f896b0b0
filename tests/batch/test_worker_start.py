"""How a sweep's local cluster starts its workers: forked from a forkserver that imported what a variant needs once,
never from the client (which may hold open FMUs, loaded binaries and threads)."""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = [pytest.mark.slow,                 # each starts a dask cluster
              pytest.mark.skipif(not sys.platform.startswith("linux"),
                                 reason="the forkserver and /proc/self/maps are Linux's (spawned workers elsewhere)")]


def worker_start(client) -> dict:
    """What the cluster's one worker process has when asked."""
    def started() -> dict:        # defined here: shipped by value, the worker imports nothing of the tests for it
        return {"modules": set(sys.modules), "parent": os.getppid(),
                "maps": Path("/proc/self/maps").read_text(), "environ": dict(os.environ)}
    return next(iter(client.run(started).values()))


def test_a_worker_starts_with_a_variants_modules_imported(project):
    """Spawned, a worker was a new interpreter that imported distributed (~0.3 s CPU) before it could take a task
    and then ncfmu's co-simulation inside its first variant (~0.25 s): forked from the forkserver it has them all
    when it starts, and its first variant imports none of ncfmu's modules (the forkserver's list is complete)."""
    from dask.distributed import Client

    from ncfmu.batch import WORKER_MODULES, local_cluster, remove_rows, run_variant
    data = (ROOT / "ssp" / "grinder_feed.ssp").read_bytes()
    digest = hashlib.sha256(data).hexdigest()

    def ncfmus() -> set[str]:
        return {m for m in sys.modules if m == "ncfmu" or m.startswith("ncfmu.")}

    def a_variant_imports() -> tuple[str, list[str]]:
        before = ncfmus()
        answer = run_variant(data, digest, {"feed.D3": 3.25}, 0.2, None, 1, None)
        remove_rows(answer["trajectory"]["path"])          # nobody fetches them
        return str(answer["row"]["status"]), sorted(ncfmus() - before)
    with local_cluster(1) as cluster, Client(cluster) as client:
        worker = worker_start(client)
        status, imported = client.submit(a_variant_imports, pure=False).result()
    assert set(WORKER_MODULES) <= worker["modules"]
    assert worker["parent"] != os.getpid()                  # not this process's child: the forkserver's
    assert status == "unfinished"                           # it ran: 0.2 s of a 32.5 s cycle
    assert imported == []


def test_a_worker_has_nothing_of_the_client(project, tmp_path, monkeypatch):
    """The client holds a system open (FMU binaries loaded from its temp dir) and a module of its own; a worker,
    forked from the forkserver (a fresh interpreter), has neither -- a worker forked from the client would have
    both, mid-use."""
    from dask.distributed import Client

    from ncfmu.batch import local_cluster
    from ncfmu.project import OpenSystem
    (tmp_path / "client_only_module.py").write_text("HELD = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import client_only_module  # noqa: F401
    opened = OpenSystem(ROOT / "ssp" / "grinder_feed.ssp")
    try:
        held = str(next(iter(opened.unpacked.values())).directory)      # an extracted FMU: this process's
        assert held in Path("/proc/self/maps").read_text()  # the client has their binaries mapped
        with local_cluster(1) as cluster, Client(cluster) as client:
            worker = worker_start(client)
    finally:
        opened.close()
        sys.modules.pop("client_only_module", None)
    assert "client_only_module" not in worker["modules"]
    assert held not in worker["maps"]


def test_a_second_cluster_forks_from_the_same_server_with_the_clients_environment_of_now(project, monkeypatch):
    """The forkserver is started once per client process and lives on: a second sweep's workers start with nothing
    to import again. A forkserver's child inherits the environment the server started with; each worker is given
    the client's environment as it is when its cluster starts."""
    from dask.distributed import Client

    from ncfmu.batch import local_cluster
    with local_cluster(1) as cluster, Client(cluster) as client:
        first = worker_start(client)
    monkeypatch.setenv("NCFMU_TEST_SET_BETWEEN_SWEEPS", "second")
    with local_cluster(1) as cluster, Client(cluster) as client:
        second = worker_start(client)
    assert second["parent"] == first["parent"] != os.getpid()
    assert {"distributed", "ncfmu.batch", "ncfmu.project"} <= second["modules"]     # imported by the server, once
    assert "NCFMU_TEST_SET_BETWEEN_SWEEPS" not in first["environ"]
    assert second["environ"].get("NCFMU_TEST_SET_BETWEEN_SWEEPS") == "second"
