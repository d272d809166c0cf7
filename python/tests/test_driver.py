"""The driver's own checks, without a cluster: loopback detection by address (names resolved,
never by prefix), result folders written only under plain relative names and only inside
themselves, and no test hook left in the shipped code."""

import os
import pathlib

import pytest

from bake_ray import executor
from bake_ray.executor import BakeRayError, _is_loopback, _write_result

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "bake_ray"


@pytest.mark.parametrize("address", [
    "127.0.0.1:6379", "ray://127.0.0.1:10001", "127.8.9.10:1", "localhost:6379",
    "[::1]:6379", "::1", "ray://localhost",
])
def test_loopback_addresses_are_loopback(address):
    assert _is_loopback(address)


@pytest.mark.parametrize("address", [
    "127.evil.example:6379", "ray://127.evil.example:10001", "10.0.0.1:6379",
    "8.8.8.8:6379", "[2001:db8::1]:6379", "", "ray://:10001", "127.0.0.1.nip.invalid:1",
])
def test_other_addresses_are_not(address):
    assert not _is_loopback(address)


def result(files, rels=None):
    rels = list(files) if rels is None else rels
    return {
        "id": "s",
        "files": files,
        "report": {"id": "s", "outputs": [{"rel": r, "size": 1, "hash": "x"} for r in rels]},
    }


@pytest.mark.parametrize("rel", [
    "../escape.exr", "../../etc/x", "/abs.exr", "a/../../b", "a//b", "./a", "a\\b", "",
])
def test_result_names_are_checked_like_the_workers_inputs(tmp_path, rel):
    folder = tmp_path / "r"
    with pytest.raises(BakeRayError):
        _write_result(str(folder), result({rel: b"x"}))
    assert not folder.exists(), "nothing written"
    assert sorted(os.listdir(tmp_path)) == []


def test_a_report_must_list_exactly_the_files(tmp_path):
    with pytest.raises(BakeRayError):
        _write_result(str(tmp_path / "r"), result({"a.exr": b"x"}, rels=["a.exr", "b.exr"]))
    with pytest.raises(BakeRayError):
        _write_result(str(tmp_path / "r2"), result({"a.exr": b"x", "b.exr": b"y"}, rels=["a.exr"]))


def test_good_results_are_written_inside_their_folder(tmp_path):
    folder = tmp_path / "r"
    _write_result(str(folder), result({"cube/px.exr": b"1", "dfg.exr": b"2"}))
    assert (folder / "files" / "cube" / "px.exr").read_bytes() == b"1"
    assert (folder / "files" / "dfg.exr").read_bytes() == b"2"
    assert (folder / "stage.json").exists()


def test_no_test_hook_in_the_shipped_code():
    for f in PACKAGE.glob("*.py"):
        text = f.read_text()
        assert "BAKE_RAY_TEST" not in text and "kill_once" not in text, f
    assert not hasattr(executor, "KILL_ONCE_ENV")
