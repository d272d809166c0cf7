"""The driver: plans with `bake plan --json`, restores what the cache holds with `bake commit
--restore`, submits one Ray task per stage to run (its dependencies are the tasks of the stages
it reads, so Ray moves their outputs through the object store), and commits each finished
stage with `bake commit` as soon as it is done: the same commit code, journal and cache as
`bake run`, so an interrupted run keeps every committed stage and the next run resumes.
"""

import ipaddress
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time

from .task import find_bake, run_stage

#: Stage statuses, as `bake run --json` words them.
RAN, RESTORED, UP_TO_DATE, SKIPPED, FAILED, BLOCKED = (
    "ran",
    "restored",
    "up-to-date",
    "skipped",
    "failed",
    "blocked",
)


class BakeRayError(Exception):
    """A problem before any stage ran (no binary, an invalid pipeline); `code` is the exit code."""

    def __init__(self, message, code=2):
        super().__init__(message)
        self.code = code


class _InterruptFlag:
    """A SIGINT handler that records the first Ctrl-C and raises on the second; a no-op
    outside the main thread, where Python cannot install signal handlers."""

    def __init__(self):
        self.set = False
        self._installed = threading.current_thread() is threading.main_thread()
        if self._installed:
            self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum, frame):
        if self.set:
            raise KeyboardInterrupt
        self.set = True

    def restore(self):
        if self._installed:
            # None: the previous handler was not installed from Python; the default stands in.
            signal.signal(signal.SIGINT, self._previous or signal.default_int_handler)
            self._installed = False


def locate_bake(bin_dir=None):
    """The driver's `bake`: --bin-dir, then $BAKE_RAY_BIN_DIR, then PATH."""
    if bin_dir:
        path = os.path.join(bin_dir, "bake")
        if not os.path.isfile(path):
            raise BakeRayError("%s: no `bake` binary there (--bin-dir)" % path, 4)
        return os.path.abspath(path)
    found = find_bake(None)
    if found is None:
        raise BakeRayError(
            "no `bake` binary: pass --bin-dir, set BAKE_RAY_BIN_DIR or put it on PATH", 4
        )
    return os.path.abspath(found)


def _call(argv):
    """Runs a `bake` command; on Ctrl-C waits for it (it handles SIGINT itself, finishing a
    commit in flight) instead of killing it mid-commit."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        out, err = proc.communicate()
    except KeyboardInterrupt:
        proc.wait()
        raise
    return proc.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace")


def plan(bake, pipeline):
    """`bake plan PIPELINE --json`."""
    code, out, err = _call([bake, "plan", pipeline, "--json"])
    if code != 0:
        raise BakeRayError(err.strip() or "bake plan exited with %d" % code, code)
    return json.loads(out)


def commit(bake, pipeline, results=(), restore=()):
    """`bake commit`: result folders and stages to restore -> {stage id: result}."""
    argv = [bake, "commit", pipeline, "--json"]
    for r in restore:
        argv += ["--restore", r]
    argv += list(results)
    code, out, err = _call(argv)
    if code not in (0, 1) or not out.strip():
        raise BakeRayError(err.strip() or "bake commit exited with %d" % code, code or 4)
    return {r["id"]: r for r in json.loads(out)}


def _safe_rel(rel):
    """A plain relative path with `/` separators: no absolute path, no `.` or `..`, no empty or
    backslashed part (what the worker accepts for its inputs, and `bake` for its outputs)."""
    if not isinstance(rel, str) or not rel or rel.startswith("/") or "\\" in rel or "\0" in rel:
        return False
    return all(p not in ("", ".", "..") for p in rel.split("/"))


def _write_result(folder, result):
    """Writes a task's result as a result folder (`stage.json` and `files/`), each file's name
    checked as the worker checks its inputs' (a plain relative path), and every write kept
    inside the folder (no symlink followed: the folder is new and only this function writes
    it). The report must list exactly the files returned."""
    files = result["files"]
    listed = [o.get("rel") for o in result["report"].get("outputs", [])]
    for rel in list(files) + listed:
        if not _safe_rel(rel):
            raise BakeRayError("stage '%s' returned an unsafe file name %r" % (result.get("id"), rel), 2)
    if sorted(listed) != sorted(files):
        raise BakeRayError("stage '%s' returned files its report does not list" % result.get("id"), 2)
    os.makedirs(folder)
    root = os.path.realpath(os.path.join(folder, "files"))
    for rel, data in files.items():
        path = os.path.join(folder, "files", *rel.split("/"))
        os.makedirs(os.path.dirname(path), exist_ok=True)
        if not os.path.realpath(path).startswith(root + os.sep):
            raise BakeRayError("stage '%s': %r leads out of its result folder" % (result.get("id"), rel), 2)
        # O_EXCL | O_NOFOLLOW: never through a link, never over a file already written.
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
    with open(os.path.join(folder, "stage.json"), "w") as f:
        json.dump(result["report"], f)


def _host_of(address):
    """The host part of a Ray address: `ray://host:port`, `host:port`, `[v6]:port`, `host`."""
    rest = address.split("://")[-1].strip()
    if rest.startswith("["):
        return rest[1:].split("]", 1)[0]
    if rest.count(":") > 1:  # a bare IPv6 address
        return rest
    return rest.rsplit(":", 1)[0] if ":" in rest else rest


def _is_loopback(address):
    """Whether `address` names this machine's loopback interface: by address (ipaddress), a name
    resolved first, and every address it resolves to must be loopback (`127.evil.example` is a
    name like any other, not 127.x.y.z)."""
    host = _host_of(address)
    if not host:
        return False
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None)
    except (socket.gaierror, UnicodeError, OSError):
        return False
    addrs = {info[4][0].split("%", 1)[0] for info in infos}
    try:
        return bool(addrs) and all(ipaddress.ip_address(a).is_loopback for a in addrs)
    except ValueError:
        return False


def _first_line(e):
    text = str(e).strip().splitlines()
    return text[-1] if text else type(e).__name__


def run(
    pipeline,
    address=None,
    bin_dir=None,
    max_retries=3,
    num_cpus=1,
    spread=True,
    log=None,
):
    """Runs `pipeline` on Ray. Returns the report (a dict, what `--json` prints)."""
    loopback = address is None or _is_loopback(address)
    if loopback:
        # Ray rewrites a loopback address to this machine's outward IP (for remote workers);
        # this switch (read when `ray` is imported) keeps a local cluster on 127.0.0.1.
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

    t0 = time.time()
    log = log or (lambda msg: None)
    bake = locate_bake(bin_dir)
    p = plan(bake, pipeline)
    stages = p["stages"]
    by_id = {s["id"]: s for s in stages}
    report = {
        s["id"]: {
            "id": s["id"],
            "kind": s["kind"],
            "status": None,
            "reason": s["reason"],
            "seconds": 0.0,
            "node": None,
        }
        for s in stages
    }
    for s in stages:
        if s["action"] == "skip":
            report[s["id"]]["status"] = SKIPPED
        elif s["action"] == "up-to-date":
            report[s["id"]]["status"] = UP_TO_DATE

    restore = [s["id"] for s in stages if s["action"] == "restore"]
    if restore:
        for sid, r in commit(bake, pipeline, restore=restore).items():
            st = report[sid]
            st["status"] = {"restored": RESTORED, "up-to-date": UP_TO_DATE}.get(r["status"], FAILED)
            st["reason"] = r["reason"]
            if st["status"] == FAILED:
                log("bake-ray: error: stage '%s': %s" % (sid, r["reason"]))

    to_run = [s for s in stages if s["action"] == "run"]
    submitted = 0
    nodes = []
    interrupted = False
    started_ray = False
    if to_run:
        # Ctrl-C is taken between stages, never inside one: a KeyboardInterrupt raised in the
        # middle of a commit or of a temporary folder's removal escapes as another error (an
        # interrupted rmtree raised EBADF in CI) and the completed stages were not reported;
        # one raised inside ray.init was swallowed. The first SIGINT sets a flag the driver
        # polls; a second one interrupts at once.
        stop = _InterruptFlag()
        try:
            import ray  # only when there is work: a run with nothing to do starts no Ray

            if not ray.is_initialized():
                # A local instance, or a cluster on this machine, stays on 127.0.0.1; a remote
                # cluster (--address HOST:PORT) is joined from this machine's outward address.
                kwargs = dict(log_to_driver=False, configure_logging=False)
                if loopback:
                    kwargs["_node_ip_address"] = "127.0.0.1"
                if address is None:
                    kwargs["include_dashboard"] = False
                # "local": a new instance, never one found through RAY_ADDRESS or /tmp/ray.
                ray.init(address=address or "local", **kwargs)
                started_ray = True
            nodes = sorted(n["NodeID"] for n in ray.nodes() if n.get("Alive"))
            options = dict(num_cpus=num_cpus, max_retries=max_retries, retry_exceptions=False)
            if spread:
                options["scheduling_strategy"] = "SPREAD"
            remote = ray.remote(run_stage).options(**options)
            refs = {}
            shipped = {}

            def ship(path):
                if path not in shipped:
                    with open(path, "rb") as f:
                        shipped[path] = ray.put(f.read())
                return shipped[path]

            failed_before = {sid for sid, r in report.items() if r["status"] == FAILED}
            for s in to_run:  # the plan lists stages in dependency order
                if stop.set:
                    break  # interrupted while Ray started: submit nothing more
                entry = s["entry"]
                slots, blobs = [], []
                blocked_by = None
                for k, read in enumerate(entry["reads"]):
                    up = read.get("stage")
                    if up is not None and up in refs:
                        slots.append(["stage", k])
                        blobs.append(refs[up])
                        continue
                    if up is not None and (up in failed_before or report[up]["status"] == BLOCKED):
                        blocked_by = up
                        break
                    # An input, or a stage built before this run: its files from this machine
                    # (a built stage's `rel` already starts with its folder, its prefix).
                    for f in read["files"]:
                        slots.append(["file", k, f["rel"]])
                        blobs.append(ship(f["path"]))
                if blocked_by is not None:
                    report[s["id"]].update(status=BLOCKED, reason="not run: '%s' failed" % blocked_by)
                    continue
                spec = {"entry": entry, "bake": bake, "slots": slots}
                refs[s["id"]] = remote.remote(spec, *blobs)
                submitted += 1
                log("bake-ray: submitted %s (%s)" % (s["id"], s["reason"]))

            pending = {ref: sid for sid, ref in refs.items()}
            work = tempfile.mkdtemp(prefix="bake-ray-")
            try:
                while pending and not stop.set:
                    ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.25)
                    if not ready:
                        continue
                    # Commit every finished stage at once (one `bake commit` for several).
                    ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0)
                    batch = []
                    for ref in ready:
                        sid = pending.pop(ref)
                        st = report[sid]
                        try:
                            res = ray.get(ref)
                        except Exception as e:  # the worker crashed more than max_retries times
                            ups = [r.get("stage") for r in by_id[sid]["entry"]["reads"]]
                            bad = [u for u in ups if u and report[u]["status"] in (FAILED, BLOCKED)]
                            if bad:
                                st.update(status=BLOCKED, reason="not run: '%s' failed" % bad[0])
                            else:
                                st.update(status=FAILED, reason="task failed: %s" % _first_line(e))
                                log("bake-ray: error: stage '%s': %s" % (sid, st["reason"]))
                            continue
                        st["node"] = res.get("node")
                        st["seconds"] = res.get("seconds", 0.0)
                        if res.get("blocked"):
                            st.update(status=BLOCKED, reason="not run: '%s' failed" % res["blocked"])
                        elif not res.get("ok"):
                            st.update(status=FAILED, reason=res.get("error", "failed"))
                            log("bake-ray: error: stage '%s': %s" % (sid, st["reason"]))
                        else:
                            folder = os.path.join(work, "%d" % len(os.listdir(work)))
                            try:
                                _write_result(folder, res)
                            except BakeRayError as e:
                                shutil.rmtree(folder, ignore_errors=True)
                                st.update(status=FAILED, reason=str(e))
                                log("bake-ray: error: stage '%s': %s" % (sid, st["reason"]))
                                continue
                            batch.append((sid, folder))
                    if batch:
                        done = commit(bake, pipeline, results=[f for _, f in batch])
                        for sid, folder in batch:
                            r = done.get(sid, {"status": "failed", "reason": "not committed"})
                            st = report[sid]
                            if r["status"] == "failed":
                                st.update(status=FAILED, reason=r["reason"])
                                log("bake-ray: error: stage '%s': %s" % (sid, r["reason"]))
                            else:
                                st["status"] = RAN if r["status"] == "ran" else UP_TO_DATE
                                log("bake-ray: ran %s on node %s (%.2f s)" % (sid, (st["node"] or "?")[:8], st["seconds"]))
                            shutil.rmtree(folder, ignore_errors=True)
            except KeyboardInterrupt:
                stop.set = True
            finally:
                # A Ctrl-C after the last stage was committed interrupted nothing.
                interrupted = stop.set and any(report[s["id"]]["status"] is None for s in to_run)
                # No ray.cancel of the pending tasks: cancelling a task whose dependency is being
                # resolved races Ray's own bookkeeping, and the driver's core worker aborts
                # ("Check failed: submitted_task_ref_count > 0", reference_counter.cc; seen in CI
                # on ray 2.60.0; ray-project/ray#55131 and PR #56123 fix only the actor-task
                # path). ray.shutdown() below ends this driver's job instead, and Ray kills the
                # job's workers with it (a stage's `bake` dies with its worker: task.py). Only a
                # caller that brought its own Ray session (started_ray False) keeps the tasks:
                # they run out and their results are dropped, none is committed.
                shutil.rmtree(work, ignore_errors=True)
                if started_ray:
                    ray.shutdown()
        finally:
            stop.restore()

    for st in report.values():
        if st["status"] is None:
            st["status"] = "interrupted" if interrupted else FAILED
    return {
        "pipeline": p["pipeline"],
        "output": p["output"],
        "nodes": nodes,
        "tasks_submitted": submitted,
        "interrupted": interrupted,
        "seconds": time.time() - t0,
        "stages": [report[s["id"]] for s in stages],
    }
