"""TFRecord framing and tf.Example messages, without TensorFlow."""

from scenariomax.io.example import decode_example, encode_example
from scenariomax.io.tfrecord import RecordError, TFRecordWriter, count_records, iter_records, masked_crc32c

__all__ = ["RecordError", "TFRecordWriter", "count_records", "iter_records", "masked_crc32c", "encode_example",
           "decode_example"]
