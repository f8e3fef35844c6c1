"""Tests of vdps_hil.batch.keys: the resume key changes with every ingredient (input bytes,
options, vehicle/model file contents, effect list, tool version) and with nothing else; the
digest cache avoids rereading unchanged files and notices changed ones."""

from __future__ import annotations

import hashlib
import json
import os
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil import __version__
from vdps_hil.batch.keys import DigestCache, canonical_json, file_digest, task_key, tool_version


@pytest.fixture
def files(tmp_path, rng):
    rec = tmp_path / "drive.mcap"
    rec.write_bytes(rng.bytes(3 * (1 << 20) + 17))  # more than one read block
    veh = tmp_path / "model.toml"
    veh.write_text('name = "m"\nmass_kg = 1500.0\n')
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("a = 1\n")
    return rec, veh, cfg


def _key(rec, veh, cfg, **over):
    args = dict(kind="replay", input_digest=file_digest(rec), config={"period_s": 0.01, "b": [1, 2]},
                files={"vehicle": veh, "config": cfg}, effects=["drag", "imu_bias"], tool="0.1.0+src.x")
    args.update(over)
    return task_key(args.pop("kind"), args.pop("input_digest"), **args)


def test_file_digest_is_the_sha256_of_the_bytes(files):
    rec = files[0]
    assert file_digest(rec) == "sha256:" + hashlib.sha256(rec.read_bytes()).hexdigest()


def test_key_changes_with_each_ingredient_and_nothing_else(files, tmp_path):
    rec, veh, cfg = files
    base = _key(rec, veh, cfg)
    assert re.fullmatch(r"sha256:[0-9a-f]{64}", base)
    assert _key(rec, veh, cfg) == base  # deterministic
    # order of options and effects, duplicate effects and dict insertion order do not matter
    assert _key(rec, veh, cfg, config={"b": [1, 2], "period_s": 0.01}) == base
    assert _key(rec, veh, cfg, effects=["imu_bias", "drag", "drag"]) == base
    # paths do not matter, contents do: a copy of the vehicle file elsewhere has the same key
    copy = tmp_path / "sub"
    copy.mkdir()
    (copy / "v.toml").write_bytes(veh.read_bytes())
    assert _key(rec, copy / "v.toml", cfg) == base
    changed = {
        "input": _key(rec, veh, cfg, input_digest="sha256:" + "0" * 64),
        "option": _key(rec, veh, cfg, config={"period_s": 0.02, "b": [1, 2]}),
        "list order in an option": _key(rec, veh, cfg, config={"period_s": 0.01, "b": [2, 1]}),
        "effect": _key(rec, veh, cfg, effects=["drag"]),
        "tool": _key(rec, veh, cfg, tool="0.1.1+src.x"),
        "kind": _key(rec, veh, cfg, kind="diagnose"),
        "file role": _key(rec, veh, cfg, files={"vehicle": veh}),
    }
    veh.write_text('name = "m"\nmass_kg = 1501.0\n')
    changed["vehicle content"] = _key(rec, veh, cfg)
    assert base not in changed.values()
    assert len(set(changed.values())) == len(changed)


def test_input_bytes_change_the_key(files):
    rec, veh, cfg = files
    base = _key(rec, veh, cfg)
    data = bytearray(rec.read_bytes())
    data[-1] ^= 1  # one bit at the very end
    rec.write_bytes(bytes(data))
    assert _key(rec, veh, cfg) != base


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.text(max_size=5), st.one_of(
    st.integers(), st.floats(allow_nan=True), st.text(max_size=5), st.booleans(), st.none()),
    max_size=6))
def test_canonical_json_ignores_key_order_and_accepts_non_finite_floats(d):
    rev = dict(reversed(list(d.items())))
    assert canonical_json(d) == canonical_json(rev)
    json.loads(canonical_json(d))  # valid JSON (nan/inf spelled as strings)


def test_unkeyable_values_are_refused():
    with pytest.raises(TypeError, match="resume key"):
        task_key("replay", None, config={"x": object()}, tool="t")


def test_tool_version_is_the_package_version_plus_a_source_digest():
    v = tool_version()
    assert re.fullmatch(re.escape(__version__) + r"\+src\.[0-9a-f]{12}", v)
    assert tool_version() == v  # computed once per process
    # the default tool in a key is this version
    assert task_key("k", None) == task_key("k", None, tool=v)


def test_digest_cache_reuses_unchanged_files_and_rereads_changed_ones(files, tmp_path):
    rec, veh, _ = files
    path = tmp_path / ".digests.json"
    c = DigestCache(path)
    d1 = c.digest(rec)
    c.digest(veh)
    assert (c.hits, c.misses) == (0, 2)
    c.save()
    c2 = DigestCache(path)
    assert c2.digest(rec) == d1 and (c2.hits, c2.misses) == (1, 0)
    # same size, new content and a new mtime: reread
    data = bytearray(rec.read_bytes())
    data[0] ^= 0xFF
    rec.write_bytes(bytes(data))
    st = rec.stat()
    os.utime(rec, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    d2 = c2.digest(rec)
    assert d2 != d1 and d2 == file_digest(rec) and c2.misses == 1
    # disabled: always reads; a damaged cache file is ignored
    off = DigestCache(path, enabled=False)
    off.digest(rec)
    assert off.misses == 1 and off.hits == 0
    path.write_text("{not json")
    assert DigestCache(path).digest(rec) == d2
