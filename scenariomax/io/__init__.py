"""TFRecord framing and tf.Example messages, without TensorFlow."""

from scenariomax.io.example import decode_example, encode_example
from scenariomax.io.gzip_members import COMPRESSIONS
from scenariomax.io.tfrecord import (
    RecordError,
    TFRecordWriter,
    count_records,
    file_compression,
    iter_records,
    masked_crc32c,
)

__all__ = ["COMPRESSIONS", "RecordError", "TFRecordWriter", "count_records", "file_compression", "iter_records",
           "masked_crc32c", "encode_example", "decode_example"]
