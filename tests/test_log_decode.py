"""`sherpa log decode`: a known sequence of frames written in each python-can format (and a
hand-written candump -L file) decodes to the expected meaning (goldens)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from sherpa_cli.elmo.codec import encode_error_reply, encode_query, encode_reply, encode_set
from sherpa_cli.log.candecode import Frame, FrameDecoder, parse_candump_line
from sherpa_cli.log.capture import channel_for, read_frames

BUSES = ["can0", "can1", "can2"]  # the bundled config's buses, in order
T0 = 1700000000.0


def _sdo(cmd: int, index: int, sub: int, data: bytes = b"") -> bytes:
    return struct.pack("<BHB", cmd, index, sub) + data.ljust(4, b"\0")


def known_sequence() -> list[tuple[str, int, bytes]]:
    """(bus, COB-ID, data) of a session: NMT, boot-up, SDO reads (one segmented), a TPDO mapped
    through SDO, SYNC and the mapped TPDO, interpreter traffic with an error, EMCY, an abort."""
    name = b"Whistle 10/60"
    frames = [
        ("can1", 0x728, b"\x00"),                                        # boot-up node 40
        ("can1", 0x000, b"\x01\x00"),                                    # NMT start all
        ("can1", 0x728, b"\x05"),                                        # heartbeat operational
        ("can1", 0x628, _sdo(0x40, 0x1017, 0)),                          # SDO read 0x1017
        ("can1", 0x5A8, _sdo(0x4B, 0x1017, 0, struct.pack("<H", 1000))),
        ("can1", 0x628, _sdo(0x40, 0x1008, 0)),                          # segmented upload
        ("can1", 0x5A8, _sdo(0x41, 0x1008, 0, struct.pack("<I", len(name)))),
        ("can1", 0x628, bytes([0x60]) + bytes(7)),
        ("can1", 0x5A8, bytes([0x00]) + name[:7]),
        ("can1", 0x628, bytes([0x70]) + bytes(7)),
        ("can1", 0x5A8, bytes([0x00 | ((7 - 6) << 1) | 0x01, *name[7:]]) + bytes(1)),
    ]
    for sub, value in ((0, 0), (1, 0x60640020), (2, 0x60690020), (0, 2)):  # map TPDO1: PX, VX
        frames += [("can1", 0x628, _sdo(0x23 if sub else 0x2F, 0x1A00, sub, struct.pack("<I", value)[:4 if sub else 1])),
                   ("can1", 0x5A8, _sdo(0x60, 0x1A00, sub))]
    frames += [
        ("can1", 0x628, _sdo(0x2F, 0x1800, 2, b"\x01")), ("can1", 0x5A8, _sdo(0x60, 0x1800, 2)),
        ("can1", 0x080, b""),                                            # SYNC
        ("can1", 0x1A8, struct.pack("<ii", -1234, 5678)),                # TPDO1 by its mapping
        ("can1", 0x328, encode_query("PX")),
        ("can1", 0x2A8, encode_reply("PX", 0, -1234, False)),
        ("can1", 0x328, encode_set("AC", 0, 150000)),
        ("can1", 0x2A8, encode_error_reply("AC", 0, 57)),
        ("can1", 0x0A8, struct.pack("<HBBHH", 0x8110, 0x11, 0, 0, 0x2A8)),  # EMCY: lost COB
        ("can2", 0x63C, _sdo(0x40, 0x2F99, 0)),
        ("can2", 0x5BC, _sdo(0x80, 0x2F99, 0, struct.pack("<I", 0x06020000))),  # abort
        ("can0", 0x70A, b"\x7f"),
        ("can0", 0x7FF, b"\x01\x02"),                                    # nothing CANopen knows
    ]
    return frames


def write_capture(path: Path) -> None:
    import can

    with can.Logger(str(path)) as writer:
        for i, (bus, cob, data) in enumerate(known_sequence()):
            writer.on_message_received(can.Message(
                timestamp=T0 + i * 0.001, arbitration_id=cob, data=data, is_extended_id=False,
                channel=channel_for(path.suffix, bus, BUSES)))


@pytest.mark.golden
@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv", ".trc"])
def test_each_format_decodes_to_the_known_meaning(cli, golden, tmp_path, suffix):
    path = tmp_path / f"capture{suffix}"
    write_capture(path)
    result = cli("log", "decode", str(path))
    assert result.exit_code == 0, result.stderr
    text = result.transcript().replace(str(tmp_path), "TMP")
    golden(f"log-decode-{suffix[1:]}.txt", text)


def test_formats_agree_with_each_other(cli, tmp_path):
    """Apart from the bus column of .csv (no channel stored), every format means the same."""
    outputs = {}
    for suffix in (".log", ".asc", ".blf", ".trc"):
        path = tmp_path / f"c{suffix}"
        write_capture(path)
        outputs[suffix] = cli("log", "decode", str(path)).stdout
    assert len(set(outputs.values())) == 1, outputs


CANDUMP_BY_HAND = """\
# written by hand, as `candump -L can0 can1` prints
(1700000000.000000) can1 000#0100
(1700000000.001000) can1 080#
(1700000000.002000) can1 328#50580000
(1700000000.003000) can1 2A8#50580000D2040000
(1700000000.004000) can1 0A8#1081110000000000

(1700000000.005000) can0 70B#05
(1700000000.006000) can0 60B#4018100400000000 R
"""


@pytest.mark.golden
def test_hand_written_candump_file(cli, golden, tmp_path):
    path = tmp_path / "by-hand.txt"
    path.write_text(CANDUMP_BY_HAND)
    golden("log-decode-candump-hand.txt", cli("log", "decode", str(path)).transcript().replace(str(tmp_path), "TMP"))


def test_filters_and_json(cli, tmp_path):
    path = tmp_path / "c.log"
    write_capture(path)
    result = cli("--json", "log", "decode", str(path), "--node", "40", "--kind", "interp")
    import json

    frames = json.loads(result.stdout)["frames"]
    assert [f["fields"].get("letters", f["fields"].get("reply")) for f in frames] == ["PX", "PX", "AC", "AC"]
    assert len(frames) == 4 and all(f["node"] == 40 and f["kind"] == "interp" for f in frames)
    assert frames[1]["fields"]["value"] == -1234
    assert frames[3]["fields"]["error_code"] == 57
    only_can2 = cli("log", "decode", str(path), "--bus", "can2").stdout.splitlines()
    assert len(only_can2) == 2 and all("can2" in line for line in only_can2)


def test_bad_inputs_are_one_clear_message(cli, tmp_path):
    missing = cli("log", "decode", str(tmp_path / "nope.log"))
    assert missing.exit_code == 2 and "no such capture file" in missing.stderr
    bad = tmp_path / "bad.log"
    bad.write_text("(1.0) can0 123#00\nthis is not candump\n")
    result = cli("log", "decode", str(bad))
    assert result.exit_code == 2 and f"{bad}:2" in result.stderr and "Traceback" not in result.stderr
    kind = cli("log", "decode", str(bad), "--kind", "bogus")
    assert kind.exit_code == 2 and "--kind bogus" in kind.stderr


def test_decoder_never_raises_on_garbage():
    decoder = FrameDecoder()
    for cob, data in ((0x328, b"\x01"), (0x2A8, b"zz")):
        assert decoder.decode(Frame(0.0, "can0", cob, data)).kind in ("interp", "other")
    for cob, data in ((0x0A8, b"\x00"), (0x5A8, b""), (0x628, b"\x20")):  # too short for an EMCY / SDO frame
        assert decoder.decode(Frame(0.0, "can0", cob, data)).kind == "malformed"


@pytest.mark.parametrize(("cob", "text"), [
    (0x70A, "remote request (RTR) for node 10's heartbeat (node guarding)"),
    (0x080, "remote request (RTR) for the SYNC id"),
    (0x1A8, "remote request (RTR) for node 40's TPDO1"),
])
def test_a_remote_frame_is_a_remote_request_not_what_it_would_be_with_data(cob, text):
    """`70A#R` used to read as "heartbeat (empty)", `080#R` as a SYNC, a TPDO RTR as that TPDO."""
    d = FrameDecoder().decode(Frame(0.0, "can0", cob, b"", is_remote=True))
    assert (d.kind, d.text) == ("remote", text)
    assert d.as_json(0.0)["remote"] is True


@pytest.mark.parametrize(("cob", "data", "why"), [
    (0x60A, "4000100000", "SDO request with 5 byte(s) (an SDO frame has 8)"),
    (0x58A, "43001000", "SDO response with 4 byte(s)"),
    (0x000, "01", "NMT command with 1 byte(s) (an NMT command has 2)"),
    (0x080, "0102", "SYNC with 2 bytes"),
    (0x08A, "1081", "EMCY with 2 byte(s) (an EMCY has 8)"),
    (0x70A, "0505", "heartbeat with 2 byte(s) (a heartbeat has 1)"),
    (0x70A, "", "heartbeat with 0 byte(s)"),
])
def test_a_malformed_frame_is_flagged_with_what_is_wrong_never_shown_as_a_valid_request(cob, data, why):
    """`60A#4000100000` used to be shown as "SDO read 0x1000:0"."""
    d = FrameDecoder().decode(Frame(0.0, "can0", cob, bytes.fromhex(data)))
    assert d.kind == "malformed" and why in d.text, (d.kind, d.text)
    assert d.as_json(0.0)["remote"] is False and d.fields["malformed"].startswith(why.split(" (")[0])


def test_log_decode_filters_remote_and_malformed_frames(cli, tmp_path):
    path = tmp_path / "odd.log"
    path.write_text("(1.0) can0 70A#R\n(1.1) can0 60A#4000100000\n(1.2) can0 70A#05\n")
    remote = cli("log", "decode", str(path), "--kind", "remote")
    assert remote.exit_code == 0 and remote.stdout.count("\n") == 1 and "remote request (RTR)" in remote.stdout
    bad = cli("log", "decode", str(path), "--kind", "malformed")
    assert bad.exit_code == 0 and "SDO request with 5 byte(s)" in bad.stdout and "SDO read" not in bad.stdout


def test_candump_parser_reads_extended_remote_and_fd():
    assert parse_candump_line("(1.5) can0 12345678#11", "x").is_extended
    assert parse_candump_line("(1.5) can0 123#R", "x").is_remote
    assert parse_candump_line("(1.5) can0 123##1AABB", "x").data == bytes.fromhex("AABB")
    with pytest.raises(ValueError, match="x:"):
        parse_candump_line("1.5 can0 123#00", "x")


def test_read_frames_maps_channel_numbers_to_config_buses(tmp_path):
    path = tmp_path / "c.asc"
    write_capture(path)
    assert {f.bus for f in read_frames(path, BUSES)} == {"can0", "can1", "can2"}


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".csv", ".trc"])
def test_a_damaged_capture_is_one_clear_message(cli, tmp_path, suffix):
    path = tmp_path / f"damaged{suffix}"
    path.write_bytes(bytes(range(256)) * 2)
    result = cli("log", "decode", str(path))
    assert result.exit_code in (0, 2), result.stderr
    assert "Traceback" not in result.stderr
    if result.exit_code == 2:
        assert str(path) in result.stderr
