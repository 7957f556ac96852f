import gzip
import struct

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from scenariomax.io.tfrecord import (
    RecordError,
    TFRecordWriter,
    count_records,
    frame_for,
    frame_record,
    iter_record_spans,
    iter_records,
    masked_crc32c,
    read_record_at,
    write_framed,
)


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


@pytest.mark.parametrize("compression", ["none", "gzip"])
def test_a_record_written_in_pieces_is_the_frame_readers_read(tmp_path, compression):
    """Conversion workers write each frame as header, data, footer: the same bytes as `frame_for`, read back."""
    payloads = [b"", b"abc", bytes(range(256)) * 40]
    path = tmp_path / "pieces.tfrecord"
    with open(path, "wb") as stream:
        sizes = [write_framed(stream, data, compression) for data in payloads]
    assert path.read_bytes() == b"".join(frame_for(data, compression) for data in payloads)
    assert sizes == [len(frame_for(data, compression)) for data in payloads]
    assert list(iter_records(path)) == payloads


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
@example(cut=0, flip=0, mode="garbage", garbage=b"\x1f\x8b")  # the gzip magic alone: truncated gzip, at byte 2
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
        assert message.count("f.tfrecord") == 1 and "\n" not in message
        assert "byte" in message or "not a TFRecord file" in message  # where the damage is, or what the file is


# --- what a file that is not a TFRecord, or a damaged one, is called --------------------------------------------

def test_a_text_or_gzip_file_is_not_a_tfrecord_rather_than_a_crc_mismatch(tmp_path):
    text = tmp_path / "notes.tfrecord"
    text.write_text("scenario_id,x,y\n" * 20)
    with pytest.raises(RecordError) as error:
        list(iter_records(text))
    assert str(error.value) == f"{text}: not a TFRecord file (its first 12 bytes are not a record header)"
    assert error.value.path == str(text) and error.value.problem.startswith("not a TFRecord file")
    gzipped = tmp_path / "shard.tfrecord.gz"  # gzip is read (TFRecord GZIP); damaged gzip says so
    gzipped.write_bytes(b"\x1f\x8b\x08\x00" + bytes(40))
    with pytest.raises(RecordError, match="damaged gzip data|truncated gzip data"):
        list(iter_records(gzipped))
    double = tmp_path / "twice.tfrecord.gz"
    double.write_bytes(gzip.compress(gzip.compress(b"x" * 100)))
    with pytest.raises(RecordError, match="is gzip-compressed twice"):
        list(iter_records(double))
    tiny = tmp_path / "tiny.tfrecord"
    tiny.write_bytes(b"hi\n")
    with pytest.raises(RecordError, match=r"not a TFRecord file \(3 bytes, too short for a record header\)"):
        list(iter_records(tiny))


def test_damage_after_the_first_record_names_the_corrupt_record(tmp_path):
    records = [frame_record(bytes([i]) * 10) for i in range(3)]  # 26 bytes each
    damaged = bytearray(b"".join(records))
    damaged[2 * 26 + 9] ^= 0xFF  # the length CRC of record 2
    path = tmp_path / "d.tfrecord"
    path.write_bytes(bytes(damaged))
    with pytest.raises(RecordError) as error:
        list(iter_records(path))
    assert str(error.value) == f"{path}: corrupt record 2: length CRC mismatch at byte 52"
    assert str(error.value).count(str(path)) == 1


def test_count_records_reads_only_the_headers(tmp_path):
    path = tmp_path / "n.tfrecord"
    with TFRecordWriter(path) as writer:
        for i in range(7):
            writer.write(bytes(1000 * i))
    assert count_records(path) == 7 and count_records(path, limit=3) == 3
    (tmp_path / "text.tfrecord").write_text("hello, world: not records")
    with pytest.raises(RecordError, match="not a TFRecord file"):
        count_records(tmp_path / "text.tfrecord")


def test_record_spans_read_back_every_payload_and_notice_a_changed_file(tmp_path):
    payloads = [bytes([i]) * (100 * i) for i in range(6)]
    path = tmp_path / "s.tfrecord"
    with TFRecordWriter(path) as writer:
        for payload in payloads:
            writer.write(payload)
    spans = list(iter_record_spans(path))
    assert [length for _, length in spans] == [len(p) for p in payloads]
    assert [read_record_at(path, offset, length, i) for i, (offset, length) in enumerate(spans)][::-1] == payloads[::-1]
    data = bytearray(path.read_bytes())
    data[spans[3][0] + 14] ^= 0xFF  # a data byte of record 3
    path.write_bytes(bytes(data))
    with pytest.raises(RecordError, match="corrupt record 3: data CRC mismatch"):
        read_record_at(path, *spans[3], 3)
    path.write_bytes(frame_record(b"other") + frame_record(b"records"))  # replaced: record 1 is elsewhere now
    with pytest.raises(RecordError, match=r"s\.tfrecord: corrupt record 1: length CRC mismatch at byte 16"):
        read_record_at(path, *spans[1], 1)
    path.write_bytes(frame_record(b"x" * 5) + frame_record(b"y" * 2))  # same place, another length
    with pytest.raises(RecordError, match="record 1 at byte 21 changed since the file was scanned"):
        read_record_at(path, 21, 100, 1)
    path.write_bytes(frame_record(b"hello") + frame_record(b"world")[:-3])
    with pytest.raises(RecordError, match=r"truncated record at byte 21"):
        list(iter_record_spans(path))


def test_a_raw_womd_scenario_proto_is_told_apart_from_a_tf_example():
    from scenariomax.io.example import encode_example
    from scenariomax.io.record_kind import looks_like_womd_scenario
    from scenariomax.sources.womd.proto import ScenarioProto

    message = ScenarioProto()
    message.scenario_id = "abc"
    message.timestamps_seconds.extend([0.0, 0.1])
    message.tracks.add().id = 7
    assert looks_like_womd_scenario(message.SerializeToString())
    example = encode_example({"scenario/id": [b"abc"], "state/x": np.zeros(3, np.float32)})
    assert not looks_like_womd_scenario(example)
    assert not looks_like_womd_scenario(b"") and not looks_like_womd_scenario(b"\xff\xff\xff")
