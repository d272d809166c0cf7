"""bake-ray on a real two-node Ray cluster on loopback: the example pipelines give the very
bytes `bake run` gives, over both nodes; a second run submits nothing and `bake run` agrees;
a worker killed mid-stage is retried; a stage failing on a damaged input fails alone; Ctrl-C
keeps what is committed and stops the stages in flight by ending the job, not by ray.cancel."""

import json
import os
import re
import signal
import subprocess
import time

import pytest

from conftest import bake_ray

PIPELINES = ["probe", "materials", "anisotropic-scene"]


def bake(bin_dir, *args):
    return subprocess.run([os.path.join(bin_dir, "bake")] + list(args), capture_output=True,
                          text=True, timeout=600)


def tree(folder):
    """Every file under `folder` but the cache: relative path -> bytes."""
    out = {}
    for root, dirs, files in os.walk(folder):
        dirs[:] = [d for d in dirs if d != ".bake"]
        for f in files:
            p = os.path.join(root, f)
            with open(p, "rb") as fh:
                out[os.path.relpath(p, folder)] = fh.read()
    return out


def redirected(work, name, out_name):
    """A copy of pipelines/NAME.ron writing into ../OUT_NAME/NAME instead of ../out/NAME."""
    src = (work / "pipelines" / (name + ".ron")).read_text()
    text, n = re.subn(r'output: "\.\./out/', 'output: "../%s/' % out_name, src)
    assert n == 1, "the pipeline names its output folder once"
    path = work / "pipelines" / ("%s-%s.ron" % (name, out_name))
    path.write_text(text)
    return str(path)


def run_json(args, env=None):
    r = bake_ray(list(args) + ["--json"], env=env)
    assert r.stdout.strip(), "no report; stderr:\n" + r.stderr
    return r, json.loads(r.stdout)


def statuses(report):
    return {s["id"]: s["status"] for s in report["stages"]}


@pytest.mark.parametrize("name", PIPELINES)
def test_example_pipelines_are_byte_identical_to_bake_run(cluster, work, bin_dir, name):
    ref = bake(bin_dir, "run", str(work / "pipelines" / (name + ".ron")), "--quiet")
    assert ref.returncode == 0, ref.stderr
    expected = tree(work / "out" / name)
    assert expected, "bake run produced files"

    pipeline = redirected(work, name, "out-ray")
    r, report = run_json(["run", pipeline, "--address", cluster.address, "--bin-dir", bin_dir])
    assert r.returncode == 0, r.stderr
    got = tree(work / "out-ray" / name)
    assert sorted(got) == sorted(expected)
    for rel in expected:
        assert got[rel] == expected[rel], "%s differs from bake run's" % rel
    ran = [s for s in report["stages"] if s["status"] == "ran"]
    assert ran and report["tasks_submitted"] == len(ran)
    assert all(s["node"] in report["nodes"] for s in ran)
    # SPREAD is a request Ray honours for work that outlasts its scheduling: a task that ends
    # before the next one's lease is granted hands its leased worker on, so the materials
    # pipeline's three 0.03 s tasks once ran on one node in CI. The spread is checked on the
    # pipelines of five tasks or more (probe: 5, anisotropic-scene: 16), which keep a worker
    # busy long enough for Ray to lease the other node's.
    assert len(ran) >= 5 or name == "materials", "the spread check must not go vacuous"
    if len(ran) >= 5:
        assert len({s["node"] for s in ran}) >= 2, "tasks ran on one node only: %s" % ran

    # A second run has nothing to do and submits no task; `bake run` agrees.
    r2, again = run_json(["run", pipeline, "--address", cluster.address, "--bin-dir", bin_dir])
    assert r2.returncode == 0, r2.stderr
    assert again["tasks_submitted"] == 0
    assert set(statuses(again).values()) <= {"up-to-date", "skipped"}
    plain = bake(bin_dir, "run", pipeline, "--json")
    assert plain.returncode == 0, plain.stderr
    assert {s["status"] for s in json.loads(plain.stdout)["stages"]} <= {"up-to-date", "skipped"}

    # Outputs deleted by hand come back from the cache, without a task, as with `bake run`.
    gone = sorted(rel for rel in got if rel.startswith(ran[0]["id"] + os.sep))
    assert gone, "the stage folder is its id"
    for rel in gone:
        os.remove(os.path.join(str(work / "out-ray" / name), rel))
    r3, third = run_json(["run", pipeline, "--address", cluster.address, "--bin-dir", bin_dir])
    assert r3.returncode == 0, r3.stderr
    assert third["tasks_submitted"] == 0 and statuses(third)[ran[0]["id"]] == "restored"
    assert tree(work / "out-ray" / name) == expected


def killing_bin_dir(bin_dir, tmp_path, marker):
    """A bin dir whose `bake` is the real one, except that the first `bake stage` to create
    `marker` kills the Ray worker that started it (its parent) while it runs: the fault is
    injected from the test, the shipped driver has no hook for it."""
    d = tmp_path / "killing-bin"
    d.mkdir()
    wrapper = d / "bake"
    wrapper.write_text(
        "#!/bin/sh\n"
        'if [ "$1" = stage ] && (set -C; : > "%s") 2>/dev/null; then\n'
        "  sleep 0.05; kill -9 $PPID\n"
        "fi\n"
        'exec "%s" "$@"\n' % (marker, os.path.join(bin_dir, "bake"))
    )
    wrapper.chmod(0o755)
    return str(d)


def test_a_killed_worker_is_retried_with_identical_outputs(cluster, work, bin_dir, tmp_path):
    ref = bake(bin_dir, "run", str(work / "pipelines" / "probe.ron"), "--quiet")
    assert ref.returncode == 0, ref.stderr
    marker = tmp_path / "killed-once"
    pipeline = redirected(work, "probe", "out-kill")
    killing = killing_bin_dir(bin_dir, tmp_path, marker)
    r, report = run_json(["run", pipeline, "--address", cluster.address, "--bin-dir", killing])
    assert r.returncode == 0, r.stderr
    assert marker.exists(), "a worker was killed during a stage"
    assert all(s == "ran" for s in statuses(report).values())
    assert tree(work / "out-kill" / "probe") == tree(work / "out" / "probe")


def test_a_stage_failing_on_a_damaged_input_fails_alone(cluster, work, bin_dir):
    good = (work / "fixtures" / "hdri" / "sunset_256.exr").read_bytes()
    # A real EXR cut short: its header promises data that is not there.
    (work / "fixtures" / "hdri-damaged" / "truncated.exr").write_bytes(good[: len(good) // 3])
    (work / "pipelines" / "broken.ron").write_text("""Pipeline(
    output: "../out/broken",
    inputs: {
        "good": File("../fixtures/hdri/sunset_256.exr"),
        "bad": File("../fixtures/hdri-damaged/truncated.exr"),
    },
    stages: [
        (id: "bad-cube", kind: "equirect-to-cube", reads: ["bad"], params: (size: 16)),
        (id: "bad-irradiance", kind: "irradiance", reads: ["bad-cube"], params: (size: 8)),
        (id: "good-cube", kind: "equirect-to-cube", reads: ["good"], params: (size: 16)),
        (id: "good-irradiance", kind: "irradiance", reads: ["good-cube"], params: (size: 8)),
        (id: "dfg", kind: "dfg", params: (size: 16, samples: 64)),
    ],
)
""")
    pipeline = str(work / "pipelines" / "broken.ron")
    r, report = run_json(["run", pipeline, "--address", cluster.address, "--bin-dir", bin_dir])
    assert r.returncode == 1, r.stderr
    assert statuses(report) == {
        "bad-cube": "failed",
        "bad-irradiance": "blocked",
        "good-cube": "ran",
        "good-irradiance": "ran",
        "dfg": "ran",
    }
    errors = [ln for ln in r.stderr.splitlines() if "error:" in ln]
    assert len(errors) == 1 and "stage 'bad-cube'" in errors[0], r.stderr
    assert "truncated.exr" in errors[0], errors[0]
    out = work / "out" / "broken"
    assert not (out / "bad-cube").exists() and not (out / "bad-irradiance").exists()
    assert not os.path.exists(out / ".bake" / "tmp"), "no staging left"
    # The good branch equals bake run's (which fails the same way).
    plain = bake(bin_dir, "run", redirected(work, "broken", "out-plain"), "--json")
    assert plain.returncode == 1
    assert {s["id"]: s["status"] for s in json.loads(plain.stdout)["stages"]} == statuses(report)
    assert tree(out) == tree(work / "out-plain" / "broken")


def interrupt_at(work, bin_dir, out_name, prefix):
    """Runs probe.ron on a local Ray, sends one SIGINT once a stderr line starts with PREFIX;
    returns (pipeline, returncode, stderr)."""
    pipeline = redirected(work, "probe", out_name)
    proc = subprocess.Popen(
        ["python3", "-m", "bake_ray.cli", "run", pipeline, "--bin-dir", bin_dir],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ),
        cwd=os.path.join(os.path.dirname(__file__), ".."),
    )
    lines = []
    deadline = time.time() + 300
    for line in proc.stderr:
        lines.append(line)
        if line.startswith(prefix) or time.time() > deadline:
            break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    return pipeline, proc.returncode, "".join(lines) + err


def resumes_to_bake_runs_bytes(work, pipeline, out_name, bin_dir):
    r, report = run_json(["run", pipeline, "--bin-dir", bin_dir])
    assert r.returncode == 0, r.stderr
    assert tree(work / out_name / "probe") == tree(work / "out" / "probe")
    assert not os.path.exists(work / out_name / "probe" / ".bake" / "tmp"), "no staging left"
    return report


def test_without_address_a_local_ray_runs_it_and_ctrl_c_keeps_completed_stages(work, bin_dir):
    ref = bake(bin_dir, "run", str(work / "pipelines" / "probe.ron"), "--quiet")
    assert ref.returncode == 0, ref.stderr
    # Interrupt once the first stage is committed.
    pipeline, code, err = interrupt_at(work, bin_dir, "out-local", "bake-ray: ran ")
    assert "Traceback" not in err, err
    if code == 0:
        pytest.skip("the run finished before the interrupt landed")
    assert code == 130, err
    assert "interrupted; completed stages are kept" in err
    assert tree(work / "out-local" / "probe"), "the completed stage is kept"
    report = resumes_to_bake_runs_bytes(work, pipeline, "out-local", bin_dir)
    assert "up-to-date" in statuses(report).values(), "the next run resumes"


def test_ctrl_c_before_any_stage_ends_exits_130_without_a_traceback(work, bin_dir):
    # A SIGINT while stages are submitted, or inside a commit, is taken between stages (an
    # interrupt that landed inside a folder's removal once escaped as an OSError).
    ref = bake(bin_dir, "run", str(work / "pipelines" / "probe.ron"), "--quiet")
    assert ref.returncode == 0, ref.stderr
    pipeline, code, err = interrupt_at(work, bin_dir, "out-early", "bake-ray: submitted ")
    assert "Traceback" not in err, err
    assert code in (0, 130), err
    if code == 130:
        assert "interrupted; completed stages are kept" in err
    resumes_to_bake_runs_bytes(work, pipeline, "out-early", bin_dir)


def test_an_interrupt_between_submissions_ends_the_job_without_cancelling_tasks(
    work, bin_dir, monkeypatch
):
    # Ray's ray.cancel of a task whose dependency is being resolved races Ray's reference
    # counting, and the driver's core worker aborts (seen once in CI on ray 2.60.0, exit 1 for
    # 130). The race is microseconds wide, so a run from outside rarely meets it; here the
    # interrupt lands at a known point, once a stage reading another stage is submitted, and
    # the driver must end the job through ray.shutdown alone.
    import ray
    from bake_ray import executor

    def no_cancel(*args, **kwargs):
        raise AssertionError("ray.cancel called on an interrupt")

    monkeypatch.setattr(ray, "cancel", no_cancel)
    submitted = []

    def log(line):
        if line.startswith("bake-ray: submitted "):
            submitted.append(line)
            if len(submitted) == 2:
                signal.raise_signal(signal.SIGINT)  # the driver's handler takes it: no raise here

    pipeline = redirected(work, "probe", "out-inproc")
    handler = signal.getsignal(signal.SIGINT)
    report = executor.run(pipeline, bin_dir=bin_dir, log=log)
    assert len(submitted) == 2, submitted
    assert report["interrupted"] and report["tasks_submitted"] == 2, report
    assert set(statuses(report).values()) <= {"interrupted"}, statuses(report)
    assert not ray.is_initialized(), "the run's own Ray instance is shut down"
    assert signal.getsignal(signal.SIGINT) == handler, "the caller's handler is back"
    ref = bake(bin_dir, "run", str(work / "pipelines" / "probe.ron"), "--quiet")
    assert ref.returncode == 0, ref.stderr
    resumes_to_bake_runs_bytes(work, pipeline, "out-inproc", bin_dir)


def test_an_interrupt_on_a_cluster_stops_the_stages_running_there(cluster, work, bin_dir, tmp_path):
    # Without ray.cancel, what stops a running stage is the end of the driver's job: Ray kills
    # the job's workers, and a stage's process dies with its worker (PR_SET_PDEATHSIG, task.py).
    # The `bake stage` here is a stand-in that records its pid and sleeps (exec keeps the
    # death signal); `plan` and `commit` are the real binary's.
    d = tmp_path / "slow-bin"
    d.mkdir()
    pids = tmp_path / "stage-pids"
    (d / "bake").write_text(
        "#!/bin/sh\n"
        'if [ "$1" = stage ]; then echo $$ >> "%s"; exec sleep 120; fi\n'
        'exec "%s" "$@"\n' % (pids, os.path.join(bin_dir, "bake"))
    )
    (d / "bake").chmod(0o755)
    pipeline = redirected(work, "probe", "out-stopped")
    proc = subprocess.Popen(
        ["python3", "-m", "bake_ray.cli", "run", pipeline, "--address", cluster.address,
         "--bin-dir", str(d)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=os.path.join(os.path.dirname(__file__), ".."),
    )
    deadline = time.time() + 120
    while not (pids.exists() and pids.read_text().strip()) and time.time() < deadline:
        time.sleep(0.05)
    assert pids.exists(), "a stage started"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    running = [int(p) for p in pids.read_text().split()]
    deadline = time.time() + 30
    while time.time() < deadline and any(os.path.exists("/proc/%d" % p) for p in running):
        time.sleep(0.1)
    alive = [p for p in running if os.path.exists("/proc/%d" % p)]
    assert not alive, "stages still running after the interrupted job: %s" % alive
    assert not tree(work / "out-stopped" / "probe"), "nothing committed"
