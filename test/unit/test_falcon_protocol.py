"""Falcon packets (haptic_anfis.device.falcon_protocol): layout, round trips, stream reassembly."""
from __future__ import annotations

import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from haptic_anfis.device import falcon_protocol as fp

int16 = st.integers(fp.INT16_MIN, fp.INT16_MAX)
triples = st.tuples(int16, int16, int16)


def test_zero_command_layout():
    assert fp.encode_command() == b'<' + b'A' * 14 + b'>'
    assert len(fp.encode_command((1, 2, 3))) == fp.PACKET_SIZE


def test_nibbles_least_significant_first_and_twos_complement():
    pkt = fp.encode_command((0x1234, -1, fp.INT16_MIN), fp.LED_RED, homing=True)
    assert pkt[1:5] == bytes(0x41 + n for n in (4, 3, 2, 1))
    assert pkt[5:9] == b'PPPP'                    # 0xFFFF
    assert pkt[9:13] == bytes((0x41, 0x41, 0x41, 0x41 + 8))  # 0x8000
    assert pkt[13] == 0x41 + (fp.LED_RED | fp.HOMING_MODE)
    assert pkt[14] == 0x41


@given(triples, st.sampled_from([0, fp.LED_GREEN, fp.LED_BLUE, fp.LED_RED, fp.LED_MASK]),
       st.booleans())
def test_command_round_trip(motors, leds, homing):
    cmd = fp.decode_command(fp.encode_command(motors, leds, homing))
    assert cmd == fp.Command(motors, leds, homing)


@given(triples, st.integers(0, 15), st.integers(0, 7))
def test_reply_round_trip(encoders, buttons, homed):
    r = fp.decode_reply(fp.encode_reply(encoders, buttons, homed))
    assert r == fp.Reply(encoders, buttons, homed)
    assert r.all_homed == (homed == 7)
    assert r.button_tuple() == tuple((buttons >> i) & 1 for i in range(4))


def test_reply_byte13_carries_buttons_and_homed_flags():
    pkt = fp.encode_reply((0, 0, 0), buttons=0b1010, homed=0b101)
    assert pkt[13] == 0x41 + 0b1010 + (0b101 << 4)


@pytest.mark.parametrize('bad', [
    b'', b'<' + b'A' * 14, b'[' + b'A' * 14 + b'>', b'<' + b'A' * 14 + b']',
    b'<' + b'A' * 5 + b'z' + b'A' * 8 + b'>',  # 'z' is no nibble
])
def test_malformed_packets_raise(bad):
    with pytest.raises(fp.PacketError):
        fp.decode_reply(bad)
    with pytest.raises(fp.PacketError):
        fp.decode_command(bad)


def test_out_of_range_values_raise():
    with pytest.raises(fp.PacketError):
        fp.encode_command((40000, 0, 0))
    with pytest.raises(fp.PacketError):
        fp.encode_command((0, 0, 0), leds=0x10)
    with pytest.raises(fp.PacketError):
        fp.encode_reply((0, 0, 0), buttons=16)
    with pytest.raises(fp.PacketError):
        fp.encode_command((0, 0))


def test_saturate_int16():
    assert fp.saturate_int16(1e9) == fp.INT16_MAX
    assert fp.saturate_int16(-1e9) == fp.INT16_MIN
    assert fp.saturate_int16(2.6) == 3 and fp.saturate_int16(-2.6) == -3
    assert fp.saturate_int16(float('nan')) == 0


def test_parser_reassembles_a_stream_cut_anywhere():
    rng = random.Random(7)
    replies = [fp.Reply(tuple(rng.randint(-3000, 3000) for _ in range(3)), rng.randint(0, 15),
                        rng.randint(0, 7)) for _ in range(50)]
    stream = b''.join(fp.encode_reply(r.encoders, r.buttons, r.homed) for r in replies)
    for trial in range(20):
        p = fp.PacketParser()
        got, i = [], 0
        while i < len(stream):
            n = rng.randint(1, 40)
            got += p.feed(stream[i:i + n])
            i += n
        assert got == replies
        assert p.dropped_bytes == 0 and p.malformed == 0


def test_parser_resynchronises_after_garbage_and_truncation():
    good = fp.encode_reply((1, 2, 3), 1, 7)
    other = fp.encode_reply((-4, 5, -6), 0, 0)
    stream = b'\x00\x13garbage' + good + good[:7] + other + b'<AAAA\xff' + b'AAAAAAAAA>' + good
    p = fp.PacketParser()
    got = p.feed(stream)
    assert [r.encoders for r in got] == [(1, 2, 3), (-4, 5, -6), (1, 2, 3)]
    assert p.malformed >= 2 and p.dropped_bytes > 0
    # nothing left over: a following packet parses on its own
    assert p.feed(other) == [fp.decode_reply(other)]
