"""What a Ray task does for one stage, on whichever node runs it: materialise the stage's input
bytes into a temporary folder, run `bake stage` there, and return the result folder's bytes.

Nothing here assumes a filesystem shared with the driver: inputs arrive as bytes (shipped by the
driver or returned by the upstream stages' tasks), outputs leave as bytes.

Application failures (bad input, a bake error) are returned as values, not raised, so Ray does
not retry them and the stages reading them see why they cannot run; only a crash of the worker
process (killed, out of memory) is left to Ray's retries.
"""

import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

def _die_with_parent():
    """Runs in the `bake stage` child: the kernel kills it when the worker dies (Linux only), so
    a killed worker leaves no orphan bake behind."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def find_bake(hint):
    """The `bake` binary on this node: the driver's path if this node has it, else
    $BAKE_RAY_BIN_DIR/bake, else `bake` on PATH."""
    candidates = []
    if hint:
        candidates.append(hint)
    if os.environ.get("BAKE_RAY_BIN_DIR"):
        candidates.append(os.path.join(os.environ["BAKE_RAY_BIN_DIR"], "bake"))
    on_path = shutil.which("bake")
    if on_path:
        candidates.append(on_path)
    for c in candidates:
        if os.path.isfile(c) and os.access(c, os.X_OK):
            return c
    return None


def _write(path, data):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def _safe_rel(rel):
    parts = rel.split("/")
    return rel and not rel.startswith("/") and all(p not in ("", ".", "..") for p in parts)


def run_stage(spec, *blobs):
    """Runs one stage. `spec` holds the stage's `entry` (from `bake plan --json`), the driver's
    `bake` path, and `slots`: what each of `blobs` is, in order: `["file", read, rel]` (an
    input file's bytes) or `["stage", read]` (the result of the task of a stage it reads).

    Returns a dict: `ok`, `id`, `node` (Ray node id), `pid`, `seconds`, and either `report`
    (stage.json) and `files` (rel -> bytes), or `error` (one line) / `blocked` (the id of a
    failed stage it reads)."""
    t0 = time.time()
    entry = spec["entry"]
    result = {"id": entry["id"], "node": _node_id(), "pid": os.getpid(), "ok": False}
    # A stage whose upstream failed does not run (its inputs do not exist).
    for slot, blob in zip(spec["slots"], blobs):
        if slot[0] == "stage" and not blob.get("ok"):
            result["blocked"] = blob.get("id")
            result["seconds"] = time.time() - t0
            return result
    bake = find_bake(spec.get("bake"))
    if bake is None:
        result["error"] = (
            "no `bake` binary on node %s (install it there, put it on PATH or set "
            "BAKE_RAY_BIN_DIR)" % result["node"]
        )
        return result
    work = tempfile.mkdtemp(prefix="bake-ray-stage-")
    try:
        inputs = os.path.join(work, "inputs")
        os.makedirs(inputs)
        for slot, blob in zip(spec["slots"], blobs):
            read = slot[1]
            if slot[0] == "file":
                rels = [(slot[2], blob)]
            else:
                prefix = entry["reads"][read]["prefix"]
                rels = [(prefix + "/" + rel, data) for rel, data in blob["files"].items()]
            for rel, data in rels:
                if not _safe_rel(rel):
                    raise ValueError("unsafe input path %r" % rel)
                _write(os.path.join(inputs, str(read), *rel.split("/")), data)
        entry_path = os.path.join(work, "entry.json")
        with open(entry_path, "w") as f:
            json.dump(entry, f)
        out = os.path.join(work, "result")
        proc = subprocess.Popen(
            [bake, "stage", "--entry", entry_path, "--inputs", inputs, "--out", out, "--json"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
        )
        stdout, stderr = proc.communicate()
        if proc.returncode != 0:
            lines = [ln for ln in stderr.decode("utf-8", "replace").splitlines() if ln.strip()]
            errors = [ln for ln in lines if "error:" in ln]
            line = (errors or lines or ["bake stage exited with %d" % proc.returncode])[-1]
            prefix = "bake: error: stage '%s': " % entry["id"]
            result["error"] = line[len(prefix):] if line.startswith(prefix) else line
            result["code"] = proc.returncode
            return result
        report = json.loads(stdout)
        files = {}
        for o in report["outputs"]:
            with open(os.path.join(out, "files", *o["rel"].split("/")), "rb") as f:
                files[o["rel"]] = f.read()
        result.update(ok=True, report=report, files=files)
        return result
    finally:
        shutil.rmtree(work, ignore_errors=True)
        result["seconds"] = time.time() - t0


def _node_id():
    try:
        import ray

        return ray.get_runtime_context().get_node_id()
    except Exception:  # outside Ray (the unit tests call run_stage directly)
        return None
