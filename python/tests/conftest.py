"""Fixtures: the release `bake` binary, a two-node Ray cluster on loopback (torn down whatever
happens), and temporary copies of the workspace's pipelines and fixtures."""

import os
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


@pytest.fixture(scope="session")
def bin_dir():
    d = os.environ.get("BAKE_RAY_BIN_DIR") or os.path.join(ROOT, "target", "release")
    if not os.path.isfile(os.path.join(d, "bake")):
        pytest.fail("no bake binary in %s: run `cargo build --release -p bake` (make ray-test does)" % d)
    return d


@pytest.fixture(scope="session")
def cluster():
    """A head and a worker node, one CPU each, on 127.0.0.1 only."""
    from ray.cluster_utils import Cluster

    args = dict(num_cpus=1, node_ip_address="127.0.0.1", include_dashboard=False,
                object_store_memory=80 * 1024 * 1024)
    c = Cluster(initialize_head=True, head_node_args=args)
    try:
        c.add_node(**args)
        c.wait_for_nodes()
        yield c
    finally:
        c.shutdown()


@pytest.fixture
def work(tmp_path):
    """A temporary workspace laid out like the real one (pipelines/, fixtures/, out/)."""
    for rel in ("pipelines", "fixtures"):
        shutil.copytree(os.path.join(ROOT, rel), str(tmp_path / rel))
    return tmp_path


def bake_ray(args, env=None, timeout=600):
    """Runs the `bake-ray` CLI as the user would (a separate driver process)."""
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run(
        [sys.executable, "-m", "bake_ray.cli"] + list(args),
        capture_output=True, text=True, env=full_env, timeout=timeout,
        cwd=os.path.join(ROOT, "python"),
    )
