"""Measures bake-ray's per-task overhead and an example pipeline's time against `bake run`, on a
two-node Ray cluster on 127.0.0.1 (the README's numbers). Usage, from the workspace root:

    python3 python/bench/overhead.py target/release
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

from ray.cluster_utils import Cluster

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
N = 20


def timed(argv):
    t = time.time()
    r = subprocess.run(argv, capture_output=True, text=True, cwd=os.path.join(ROOT, "python"))
    assert r.returncode == 0, r.stderr
    return time.time() - t, r.stdout


def main(bin_dir):
    bin_dir = os.path.abspath(bin_dir)
    bake = os.path.join(bin_dir, "bake")
    work = tempfile.mkdtemp(prefix="bake-ray-bench-")
    shutil.copytree(os.path.join(ROOT, "pipelines"), os.path.join(work, "pipelines"))
    shutil.copytree(os.path.join(ROOT, "fixtures"), os.path.join(work, "fixtures"))
    tiny = os.path.join(work, "pipelines", "tiny-%s.ron")
    stages = ",\n".join('(id: "t%02d", kind: "dfg", params: (size: 4, samples: %d))' % (i, 8 + i)
                        for i in range(N))
    for out in ("a", "b"):
        with open(tiny % out, "w") as f:
            f.write('Pipeline(output: "../out/tiny-%s", stages: [%s])' % (out, stages))
    probe = os.path.join(work, "pipelines", "probe.ron")
    probe_b = os.path.join(work, "pipelines", "probe-b.ron")
    with open(probe) as f:
        text = f.read()
    with open(probe_b, "w") as f:
        f.write(text.replace("../out/probe", "../out/probe-b"))
    args = dict(num_cpus=1, node_ip_address="127.0.0.1", include_dashboard=False,
                object_store_memory=80 * 1024 * 1024)
    c = Cluster(initialize_head=True, head_node_args=args)
    try:
        c.add_node(**args)
        c.wait_for_nodes()
        ray_run = [sys.executable, "-m", "bake_ray.cli", "run", "--address", c.address,
                   "--bin-dir", bin_dir, "--json"]
        t_bake, _ = timed([bake, "run", tiny % "a", "--quiet", "--jobs", "2"])
        t_ray, out = timed(ray_run + [tiny % "b"])
        rep = json.loads(out)
        task = sum(s["seconds"] for s in rep["stages"]) / N
        t_noop, _ = timed(ray_run + [tiny % "b"])
        p_bake, _ = timed([bake, "run", probe, "--quiet", "--jobs", "2"])
        p_ray, out = timed(ray_run + [probe_b])
        nodes = len({s["node"] for s in json.loads(out)["stages"] if s["node"]})
    finally:
        c.shutdown()
        shutil.rmtree(work, ignore_errors=True)
    print("tiny stages (%d): bake run %.2f s, bake-ray %.2f s on 2 nodes -> %.3f s of overhead per "
          "task (wall); %.3f s per task inside the worker (materialise + bake stage + pack)"
          % (N, t_bake, t_ray, (t_ray - t_bake) / N * 2, task))
    print("a second bake-ray run (nothing to do, no task): %.2f s" % t_noop)
    print("pipelines/probe.ron: bake run %.2f s, bake-ray %.2f s (%d nodes)" % (p_bake, p_ray, nodes))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "target", "release"))
