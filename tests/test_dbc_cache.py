"""Tests of vdps_hil.codecs.dbc_cache: a description read from the cache describes and decodes
every message of the project's DBC and of the RAV4 DBC exactly as cantools does (same values,
same Python types); corrupt, foreign and stale cache files and unwritable directories are
ignored; an edited DBC misses; a fresh interpreter decoding with a warm cache never imports
cantools or python-can. Every test has its own cache directory (VDPS_CACHE_DIR)."""

from __future__ import annotations

import io
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vdps_hil.codecs import dbc_cache
from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH
from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

RAV4_DBC = Path("comma2k19_rav4_2018-08-02_seg40") / "toyota_new_mc_pt_generated.dbc"
REPO = Path(__file__).resolve().parents[1]

_SIGNAL_ATTRS = ("name", "start", "length", "byte_order", "is_signed", "is_float",
                 "is_multiplexer", "multiplexer_ids", "scale", "offset", "minimum", "maximum",
                 "unit")
_MESSAGE_ATTRS = ("name", "frame_id", "is_extended_frame", "length", "is_fd", "is_container",
                  "cycle_time")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv(dbc_cache.ENV_CACHE_DIR, str(d))
    return d


def _same(a, b) -> bool:
    """Equal with the same type (int stays int), NaN equal to NaN: bit-identical results."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return a == b


def _warm(path, strict):
    """A description loaded from the cache (the first load parses and writes it)."""
    first = dbc_cache.load_description(path, strict=strict)
    assert not first.from_cache
    desc = dbc_cache.load_description(path, strict=strict)
    assert desc.from_cache and desc._db is None  # nothing parsed by cantools
    return desc


def _check_against_cantools(desc, db, rng, payloads=40):
    """Every message: same description fields as cantools, and every payload of its length
    decodes (compiled layout + cached conversions) to cantools' scaled values. Returns the
    number of messages that compiled."""
    assert len(desc.messages) == len(db.messages)
    compiled = 0
    for m, cm in zip(desc.messages, db.messages):
        for a in _MESSAGE_ATTRS:
            assert _same(getattr(m, a), getattr(cm, a)), (m.name, a)
        assert m.is_multiplexed() == cm.is_multiplexed()
        assert len(m.signals) == len(cm.signals)
        for s, cs in zip(m.signals, cm.signals):
            for a in _SIGNAL_ATTRS:
                assert _same(getattr(s, a), getattr(cs, a)), (m.name, s.name, a)
        try:
            comp = compile_message(m)
        except NotCompilable:
            with pytest.raises(NotCompilable):  # the same verdict on cantools' message
                compile_message(cm)
            continue
        compiled += 1
        for _ in range(payloads):
            data = rng.integers(0, 256, m.length, dtype=np.uint8).tobytes()
            ref = cm.decode(data, decode_choices=False, scaling=True)
            got = {s.name: s.conversion.raw_to_scaled(r, False)
                   for s, r in zip(m.signals, comp.raw(data))}
            assert ref.keys() == got.keys()
            for k in ref:
                assert _same(got[k], ref[k]), (m.name, k, got[k], ref[k])
    return compiled


def test_cache_hit_decodes_every_vdps_message_as_cantools(cache, rng):
    desc = _warm(DEFAULT_DBC_PATH, True)
    db = dbc_cache._parse(DEFAULT_DBC_PATH.read_bytes(), True)
    assert _check_against_cantools(desc, db, rng, payloads=300) == len(db.messages)
    assert dict(desc.attributes) == {k: v.value for k, v in db.dbc.attributes.items()}
    for m, cm in zip(desc.messages, db.messages):
        assert m.attributes["VdpsKind"] == cm.dbc.attributes["VdpsKind"].value


def test_cache_hit_conversions_equal_cantools_on_every_raw_value(cache):
    """Each vdps.dbc signal's cached conversion == cantools' raw_to_scaled on all its raw values
    (bit for bit and type for type)."""
    desc = _warm(DEFAULT_DBC_PATH, True)
    db = dbc_cache._parse(DEFAULT_DBC_PATH.read_bytes(), True)
    for m, cm in zip(desc.messages, db.messages):
        for s, cs in zip(m.signals, cm.signals):
            lo = -(1 << (s.length - 1)) if s.is_signed else 0
            for r in range(lo, lo + (1 << s.length)):
                assert _same(s.conversion.raw_to_scaled(r, False),
                             cs.conversion.raw_to_scaled(r, False))


def test_cache_hit_decodes_every_rav4_message_as_cantools(cache, real_data, rng):
    """The RAV4 DBC (opendbc, non-strict, Motorola, value tables): every message described as
    cantools has it; the compiled ones decode to cantools' values; the others (overlapping or
    float signals) and frames of other lengths decode through cantools itself, parsed from the
    same bytes on demand."""
    path = real_data / RAV4_DBC
    desc = _warm(path, False)
    db = dbc_cache._parse(path.read_bytes(), False)
    compiled = _check_against_cantools(desc, db, rng)
    assert 0.5 * len(db.messages) < compiled < len(db.messages)
    for odd in (m for m in desc.messages if _compiles(m) is None):
        data = bytes(range(odd.length))
        try:
            ref = db.messages[odd.index].decode(data, decode_choices=False)
        except Exception as e:  # noqa: BLE001 - cantools' DecodeError (signal past the payload)
            with pytest.raises(type(e)):
                odd.decode(data, decode_choices=False)
            continue
        assert odd.decode(data, decode_choices=False) == ref
    m = next(m for m in desc.messages if m.length > 4 and _compiles(m) is not None)
    kw = dict(decode_choices=False, allow_truncated=True)  # a short frame: cantools decodes it
    assert m.decode(bytes(4), **kw) == db.messages[m.index].decode(bytes(4), **kw)
    assert desc._db is not None  # parsed on the first need only
    with_choices = next(s for m in desc.messages for s in m.signals if s.conversion.has_choices)
    with pytest.raises(ValueError, match="value tables"):
        with_choices.conversion.raw_to_scaled(0, True)


def _compiles(m):
    try:
        return compile_message(m)
    except NotCompilable:
        return None


def test_signal_map_decoder_from_the_cache_equals_the_one_from_cantools(cache, real_data, rng):
    """The RAV4 signal map decoder built on a cache hit and one built on cantools' database give
    the same samples and counters for frames of every DBC message, of right and wrong length."""
    from vdps_hil.adapters.signalmap import load_signalmap
    from vdps_hil.adapters.signalmap_decoder import SignalMapDecoder, load_dbc

    bm = load_signalmap("toyota_rav4_2017").buses["pt"]
    path = real_data / RAV4_DBC
    load_dbc(path, strict=False)
    desc = load_dbc(path, strict=False)
    assert desc.from_cache
    fast = SignalMapDecoder(bm, desc)
    ref = SignalMapDecoder(bm, dbc_cache._parse(path.read_bytes(), False))
    for k in range(3000):
        m = desc.messages[int(rng.integers(len(desc.messages)))]
        n = m.length if rng.random() < 0.9 else int(rng.integers(0, 9))
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert fast.decode(k, m.frame_id, data, m.is_extended_frame) == \
            ref.decode(k, m.frame_id, data, m.is_extended_frame)
    assert dict(fast.counters) == dict(ref.counters)
    assert fast.counters["decoded"] > 100 and fast.counters["dlc_mismatch"] > 0


def _cache_file(cache) -> Path:
    [f] = (cache / "dbc").glob("*.json")
    return f


def _retuned(doc, scale, rehash=False) -> str:
    """``doc`` with the first wheel speed's scale set to ``scale`` (conversion too), every other
    field intact; ``rehash``: its content_sha256 recomputed to match."""
    doc = json.loads(json.dumps(doc))
    m = next(m for m in doc["messages"] if m["name"] == "VDPS_WheelSpeedFront")
    m["signals"][0]["scale"] = scale
    m["signals"][0]["conversion"][1] = scale
    if rehash:
        doc["content_sha256"] = dbc_cache._content_sha256(doc["attributes"], doc["messages"])
    return json.dumps(doc)


@pytest.mark.parametrize("corrupt", [
    lambda doc, text: b"\x00not json",
    lambda doc, text: text[: len(text) // 2],
    lambda doc, text: json.dumps([doc]),
    lambda doc, text: json.dumps(dict(doc, format=0)),  # stale format
    lambda doc, text: json.dumps(dict(doc, parser="another cantools")),  # stale parser
    lambda doc, text: json.dumps(dict(doc, strict=not doc["strict"])),
    lambda doc, text: json.dumps(dict(doc, messages=[dict(doc["messages"][0], length="8")])),
    lambda doc, text: json.dumps(dict(doc, messages=[dict(doc["messages"][0], frame_id=True)])),
    lambda doc, text: json.dumps(dict(doc, messages=[dict(doc["messages"][0], signals=[
        dict(doc["messages"][0]["signals"][0], conversion=["exec", 1, 0, False, False])])])),
    lambda doc, text: json.dumps(dict(doc, messages=[dict(doc["messages"][0], extra=1)])),
    lambda doc, text: _retuned(doc, 0.02),  # a number of the right type changed: content hash
    lambda doc, text: _retuned(doc, 0, rehash=True),  # consistent, but a scale no decoder can use
    lambda doc, text: json.dumps(dict(doc, content_sha256="0" * 64)),
], ids=["binary", "truncated", "list", "format", "parser", "strict", "length-type",
        "bool-id", "conversion-kind", "extra-field", "tampered-scale", "zero-scale",
        "content-hash"])
def test_corrupt_or_stale_cache_file_is_ignored_and_replaced(cache, corrupt):
    dbc_cache.load_description(DEFAULT_DBC_PATH)
    f = _cache_file(cache)
    text = f.read_text()
    bad = corrupt(json.loads(text), text)
    f.write_bytes(bad if isinstance(bad, bytes) else bad.encode())
    before = dict(dbc_cache.STATS)
    desc = dbc_cache.load_description(DEFAULT_DBC_PATH)
    assert not desc.from_cache and len(desc.messages) == 7
    assert dbc_cache.STATS["rejected"] == before["rejected"] + 1
    assert dbc_cache.STATS["miss"] == before["miss"] + 1
    assert json.loads(f.read_text()) == json.loads(text)  # rewritten
    assert dbc_cache.load_description(DEFAULT_DBC_PATH).from_cache


def test_foreign_cache_file_is_ignored(cache, tmp_path):
    """Another DBC's description under this DBC's name (copied, or a hash collision) is not
    used: the file names the DBC's sha256 it describes."""
    other = tmp_path / "other.dbc"
    other.write_text(DEFAULT_DBC_PATH.read_text().replace("VDPS_SteerAngle", "VDPS_Steer"))
    a = dbc_cache.load_description(DEFAULT_DBC_PATH)
    b = dbc_cache.load_description(other)
    pa = dbc_cache.cache_path(a.sha256, True)
    pb = dbc_cache.cache_path(b.sha256, True)
    pb.write_bytes(pa.read_bytes())
    desc = dbc_cache.load_description(other)
    assert not desc.from_cache
    assert "VDPS_Steer" in {m.name for m in desc.messages}


def test_edited_dbc_misses_the_cache(cache, tmp_path):
    p = tmp_path / "vdps.dbc"
    p.write_bytes(DEFAULT_DBC_PATH.read_bytes())
    _warm(p, True)
    p.write_text(p.read_text().replace("(0.001,0) [-12.567|12.567]", "(0.002,0) [-12.567|12.567]"))
    desc = dbc_cache.load_description(p, strict=True)
    assert not desc.from_cache
    steer = next(s for m in desc.messages if m.name == "VDPS_SteerAngle" for s in m.signals
                 if s.name == "steer_wheel_angle_rad")
    assert steer.scale == 0.002 and steer.conversion.raw_to_scaled(1000, False) == 2.0
    assert len(list((cache / "dbc").glob("*.json"))) == 2
    assert not dbc_cache.load_description(p, strict=False).from_cache  # strictness is in the key


def test_unwritable_cache_directory_is_not_an_error(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory should be")
    monkeypatch.setenv(dbc_cache.ENV_CACHE_DIR, str(blocker / "cache"))
    before = dbc_cache.STATS["store_failed"]
    desc = dbc_cache.load_description(DEFAULT_DBC_PATH)
    assert not desc.from_cache and len(desc.messages) == 7
    assert dbc_cache.STATS["store_failed"] == before + 1
    assert not dbc_cache.load_description(DEFAULT_DBC_PATH).from_cache


def test_cache_location(monkeypatch, tmp_path):
    monkeypatch.delenv(dbc_cache.ENV_CACHE_DIR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert dbc_cache.cache_dir() == tmp_path / "xdg" / "vdps-hil" / "dbc"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert dbc_cache.cache_dir() == Path.home() / ".cache" / "vdps-hil" / "dbc"
    monkeypatch.setenv(dbc_cache.ENV_CACHE_DIR, str(tmp_path / "mine"))
    assert dbc_cache.cache_dir() == tmp_path / "mine" / "dbc"
    name = dbc_cache.cache_path("ab" * 32, False).name
    assert name.startswith("ab" * 32 + f".lax.v{dbc_cache.FORMAT_VERSION}.") and name.endswith(".json")


@pytest.mark.parametrize("edit,msg", [
    (("wheel_speed_radps_1 : 16|16@1- (0.01,0)", "wheel_speed_radps_1 : 16|16@1- (0,0)"),
     "VDPS_WheelSpeedFront.wheel_speed_radps_1: scale 0 "),
    (("BO_ 304 VDPS_SteerAngle: 4 SAS", "BO_ 304 VDPS_SteerAngle: 255 SAS"),
     "VDPS_SteerAngle: length 255 bytes"),
], ids=["scale-0", "dlc-255"])
def test_dbc_numbers_no_decoder_can_use_are_refused(cache, tmp_path, edit, msg):
    bad = tmp_path / "bad.dbc"
    bad.write_text(DEFAULT_DBC_PATH.read_text().replace(*edit))
    assert bad.read_text() != DEFAULT_DBC_PATH.read_text()
    with pytest.raises(dbc_cache.DbcValueError, match=msg) as e:
        dbc_cache.load_description(bad)
    assert "\n" not in str(e.value)
    assert not list((cache / "dbc").glob("*.json"))


def test_unparsable_dbc_raises_and_caches_nothing(cache, tmp_path):
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a dbc\n")
    with pytest.raises(Exception):
        dbc_cache.load_description(bad)
    assert not list((cache / "dbc").glob("*.json"))


_CHILD = """
import sys
from vdps_hil.record.decode import decode_recording
from vdps_hil.codecs import dbc_cache
kw = {} if len(sys.argv) < 3 else dict(dbc=sys.argv[2], signalmap="toyota_rav4_2017",
                                       bus_map={"vdps": "pt"})
d = decode_recording(sys.argv[1], **kw)
n = sum(1 for _ in d)
print(n, sum(d.rejected().values()), dbc_cache.STATS["hit"], dbc_cache.STATS["miss"],
      "cantools" in sys.modules, "can" in sys.modules)
"""


def _child(cache, *args) -> list[str]:
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO),
           dbc_cache.ENV_CACHE_DIR: str(cache), "HOME": str(cache)}
    out = subprocess.run([sys.executable, "-c", _CHILD, *map(str, args)], env=env,
                         capture_output=True, text=True, timeout=120, check=True)
    return out.stdout.split()


def _recording(path, frames) -> Path:
    from vdps_hil.record.writer import RecordingWriter

    with RecordingWriter(path) as w:
        for k, (aid, data) in enumerate(frames):
            w.write_can("vdps", 1_000_000 * (k + 1), {"arbitration_id": aid, "data": data})
    return path


def test_fresh_interpreter_with_warm_cache_imports_neither_cantools_nor_can(cache, tmp_path, rng):
    """Decoding a vdps recording in a new process: the first run parses the DBC (cantools),
    the second reads the cache and leaves cantools and python-can unimported."""
    from vdps_hil.codecs.can_encode import encode_steer, encode_warning, encode_wheel_speeds

    frames = []
    for k in range(50):
        for m in (*encode_wheel_speeds(rng.uniform(-50, 50, 4), k),
                  encode_steer(float(rng.uniform(-1, 1)), k),
                  encode_warning(1, 2.0, 0.1, 0.4, 0, k)):
            frames.append((m.arbitration_id, bytes(m.data)))
    rec = _recording(tmp_path / "vdps.mcap", frames)
    shutil.rmtree(cache, ignore_errors=True)  # encoding here may have filled it
    cold = _child(cache, rec)
    assert cold == ["200", "0", "1", "1", "True", "True"]  # 1 miss (map check), 1 hit (codec)
    warm = _child(cache, rec)
    assert warm == ["200", "0", "2", "0", "False", "False"]


def test_fresh_interpreter_foreign_dbc_with_warm_cache(cache, tmp_path, real_data, rng):
    """The same with the RAV4 DBC and its signal map, frames of compiled messages only."""
    path = real_data / RAV4_DBC
    desc = dbc_cache.load_description(path, strict=False)
    from vdps_hil.adapters.signalmap import load_signalmap

    mapped = set(load_signalmap("toyota_rav4_2017").buses["pt"].messages)
    ok = [m for m in desc.messages if _compiles(m) is not None and not m.is_extended_frame]
    assert {k for k in mapped if not k[1]} <= {(m.frame_id, False) for m in ok}
    frames = [(m.frame_id, rng.integers(0, 256, m.length, dtype=np.uint8).tobytes())
              for m in ok for _ in range(3)]
    rec = _recording(tmp_path / "rav4.mcap", frames)
    warm = _child(cache, rec, path)
    assert warm[2:] == ["1", "0", "False", "False"]
    assert int(warm[0]) > 0
