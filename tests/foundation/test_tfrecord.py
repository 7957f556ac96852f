import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.io.tfrecord import RecordError, TFRecordWriter, frame_record, iter_records, masked_crc32c


def test_masked_crc32c_known_value():
    # CRC32C("123456789") = 0xE3069283 (the standard check value); masking rotates right by 15 and adds a delta.
    crc = 0xE3069283
    expected = (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF
    assert masked_crc32c(b"123456789") == expected


def test_frame_layout_is_length_crc_data_crc():
    framed = frame_record(b"abc")
    assert struct.unpack("<Q", framed[:8])[0] == 3
    assert struct.unpack("<I", framed[8:12])[0] == masked_crc32c(framed[:8])
    assert framed[12:15] == b"abc"
    assert struct.unpack("<I", framed[15:19])[0] == masked_crc32c(b"abc")


def test_write_then_read_many_records(tmp_path):
    payloads = [bytes([i]) * i for i in range(50)]
    path = tmp_path / "x.tfrecord"
    with TFRecordWriter(path) as writer:
        for payload in payloads:
            writer.write(payload)
    assert list(iter_records(path)) == payloads


def test_truncated_file_names_file_and_offset(tmp_path):
    path = tmp_path / "t.tfrecord"
    path.write_bytes(frame_record(b"hello") + frame_record(b"world")[:-3])
    with pytest.raises(RecordError, match=r"t\.tfrecord: truncated record at byte 21"):
        list(iter_records(path))


def test_flipped_data_byte_is_a_crc_error(tmp_path):
    data = bytearray(frame_record(b"hello world"))
    data[14] ^= 0xFF
    path = tmp_path / "c.tfrecord"
    path.write_bytes(bytes(data))
    with pytest.raises(RecordError, match="CRC mismatch"):
        list(iter_records(path))


@settings(max_examples=30, deadline=None)
@given(cut=st.integers(min_value=0, max_value=200), flip=st.integers(min_value=0, max_value=10_000),
       mode=st.sampled_from(["truncate", "flip", "garbage"]), garbage=st.binary(max_size=64))
def test_damaged_bytes_give_a_clean_error(tmp_path_factory, cut, flip, mode, garbage):
    good = b"".join(frame_record(bytes([i % 251]) * (i * 3)) for i in range(1, 12))
    if mode == "truncate":
        data = good[: max(1, len(good) - cut - 1)]
    elif mode == "flip":
        position = flip % len(good)
        data = good[:position] + bytes([good[position] ^ 0x5A]) + good[position + 1:]
    else:
        data = garbage or b"\x01"
    path = tmp_path_factory.mktemp("fuzz") / "f.tfrecord"
    path.write_bytes(data)
    try:
        list(iter_records(path))
    except RecordError as error:
        message = str(error)
        assert "f.tfrecord" in message and "byte" in message and "\n" not in message
