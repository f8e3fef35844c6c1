"""Tests of vdps_hil.codecs.dbc_compile: the compiled bit layouts decode exactly as cantools
does, on every message of the project's DBC and on random layouts of both byte orders; the
chassis decoder's compiled path gives the same samples and counters as cantools' path."""

from __future__ import annotations

import math
import random

import pytest
from cantools.database.can import Message, Signal
from cantools.database.conversion import BaseConversion
from hypothesis import given, settings, strategies as st

from vdps_hil.codecs.can_dbc import TTR_NONE_RAW, load_dbc
from vdps_hil.codecs.can_e2e import e2e_crc
from vdps_hil.codecs.can_decode import VdpsCanDecoder, _DecodePlan
from vdps_hil.codecs.can_encode import _from_raw, encode_warning
from vdps_hil.codecs.dbc_compile import CompiledMessage, NotCompilable, compile_message

from can_checks import messages

DB = load_dbc().db


@pytest.mark.parametrize("message", DB.messages, ids=lambda m: m.name)
@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_every_vdps_message_matches_cantools(message, data):
    payload = data.draw(st.binary(min_size=message.length, max_size=message.length))
    ref = message.decode(payload, decode_choices=False, scaling=False)
    assert compile_message(message).raw_dict(payload) == ref


@settings(max_examples=400, deadline=None)
@given(m=messages(), data=st.data())
def test_random_layouts_match_cantools(m, data):
    payload = data.draw(st.binary(min_size=m.length, max_size=m.length))
    assert compile_message(m).raw_dict(payload) == m.decode(payload, decode_choices=False, scaling=False)


def test_float_and_out_of_payload_signals_are_not_compiled():
    f = Message(1, "F", 4, [Signal("f", 0, 32, "little_endian", False, conversion=BaseConversion.factory(
        is_float=True))], strict=True)
    with pytest.raises(NotCompilable):
        CompiledMessage(f)
    sig = Signal("s", 0, 16, "little_endian", False)
    m = Message(2, "M", 2, [sig], strict=True)
    m.length = 1  # a signal beyond the payload
    with pytest.raises(NotCompilable):
        CompiledMessage(m)


def test_scaled_values_equal_cantools_conversion_on_every_raw_value():
    """_DecodePlan's float(raw * scale + offset) == _from_raw == cantools' own raw_to_scaled
    for every raw value each value signal of the DBC can carry (TTR sentinel: inf)."""
    dbc = load_dbc()
    for spec in dbc.messages.values():
        plan = _DecodePlan(spec)
        cantools_sig = {s.name: s for s in dbc.db.get_message_by_name(spec.name).signals}
        for (name, _, scale, offset, ttr), sig in zip(plan.values, spec.values):
            assert name == sig.name
            lo, hi = sig.raw_min, sig.raw_max
            conv = cantools_sig[name].conversion
            for r in range(lo, hi + 1):
                x = float(conv.raw_to_scaled(r, decode_choices=False))
                if ttr and r == TTR_NONE_RAW:
                    assert _from_raw(sig, r) == math.inf
                    continue
                assert float(r * scale + offset) == x == _from_raw(sig, r)


def _frames(seed: int, n: int) -> list[tuple[int, int, bytes]]:
    """Valid-looking and corrupted frames of every message, counters mostly in sequence."""
    rng = random.Random(seed)
    dbc = load_dbc()
    ids = sorted(dbc.by_id)
    ctr = dict.fromkeys(ids, 0)
    out = []
    for k in range(n):
        aid = rng.choice(ids)
        spec = dbc.by_id[aid]
        if aid == 0x080:
            data = bytes(encode_warning(rng.randrange(4), rng.choice([None, 1.5]), 0.1, 0.5,
                                        rng.randrange(2), ctr[aid]).data)
        else:  # layout 2: the counter at its bits (Intel), the E2E CRC in byte 0
            c = spec.counter
            word = int.from_bytes(rng.randbytes(spec.dlc), "little")
            mask = ((1 << c.length_bits) - 1) << c.start_bit
            word = (word & ~mask) | ((ctr[aid] % (1 << c.length_bits)) << c.start_bit)
            data = bytearray(word.to_bytes(spec.dlc, "little"))
            if spec.crc is not None:
                data[0] = e2e_crc(data, spec.data_id)
            data = bytes(data)
        ctr[aid] = (ctr[aid] + (1 if rng.random() < 0.95 else rng.randrange(0, 5))) & 0xFF
        r = rng.random()
        if r < 0.03:
            data = data[:-1]
        elif r < 0.06:
            data = bytes([data[0] ^ 0x10]) + data[1:]
        out.append((k * 400_000, aid, data))
    return out


def test_decoder_compiled_path_equals_cantools_path():
    """The chassis decoder with the compiled layouts and with cantools' decode (plans with no
    compiled message) gives the same samples and the same counters on 5000 mixed frames."""
    fast, slow = VdpsCanDecoder(), VdpsCanDecoder()
    for p in slow._plan.values():
        p.compiled = None
    for t, aid, data in _frames(3, 5000):
        assert fast.decode(t, aid, data) == slow.decode(t, aid, data)
    assert fast.counters == slow.counters
    assert sum(c["accepted"] for k, c in fast.counters.items() if k != "bus") > 3000


@settings(max_examples=400, deadline=None)
@given(m=messages(), data=st.data())
def test_packing_random_layouts_equals_cantools_encoding(m, data):
    """CompiledMessage.pack writes what cantools' encode writes for raw values anywhere in each
    signal's bit field, signed or not, on random layouts of both byte orders; and decodes back."""
    comp = compile_message(m)
    raws = []
    for s in m.signals:
        lo, hi = (-(1 << (s.length - 1)), (1 << (s.length - 1)) - 1) if s.is_signed else (0, (1 << s.length) - 1)
        raws.append(data.draw(st.integers(lo, hi)))
    packed = comp.pack(raws)
    assert packed == m.encode(dict(zip(comp.names, raws)), scaling=False, strict=False)
    assert comp.raw(packed) == raws


def test_packing_a_message_with_both_byte_orders_and_refusing_what_does_not_fit():
    le = Signal("le", 0, 12, "little_endian", True)
    be = Signal("be", 23, 10, "big_endian", False)  # MSB at bit 23 (byte 2), then into byte 3
    m = Message(0x321, "Mixed", 4, [le, be], strict=True)
    comp = compile_message(m)
    for raws in ([-2048, 1023], [2047, 0], [-1, 517], [0, 0]):
        assert comp.pack(raws) == m.encode(dict(zip(comp.names, raws)), scaling=False, strict=False)
        assert comp.raw(comp.pack(raws)) == raws
    for bad in ([2048, 0], [-2049, 0], [0, 1024], [0, -1]):
        with pytest.raises(ValueError, match="does not fit"):
            comp.pack(bad)
