"""`parse_json`: the fast parser's documents are the standard parser's; what only the standard one reads still reads."""

import json
import math
from pathlib import Path

import pytest

from scenariomax.sources.base import parse_json

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"


def test_real_gpudrive_map_parses_as_the_standard_parser_does():
    files = sorted((REALDATA / "gpudrive").glob("*.json"))
    if not files:
        pytest.skip(f"no GPUDrive JSON under {REALDATA / 'gpudrive'}")
    data = files[0].read_bytes()
    assert parse_json(data) == json.loads(data.decode("utf-8"))


def test_nan_and_infinity_literals_still_read():
    doc = parse_json(b'{"x": NaN, "y": [Infinity, -Infinity, 1.5]}')
    assert math.isnan(doc["x"]) and doc["y"][:2] == [math.inf, -math.inf] and doc["y"][2] == 1.5


@pytest.mark.parametrize("data, reason", [(b'{"x": [1, 2', "invalid JSON: "), (b"\xff{}", "not UTF-8 text")])
def test_errors_keep_their_one_line_reason(data, reason):
    with pytest.raises(ValueError, match=reason) as error:
        parse_json(data)
    assert "\n" not in str(error.value)
