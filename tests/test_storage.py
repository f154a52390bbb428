"""results.json's layout: the same JSON as json.dumps, laid out for reading, written fast."""

from __future__ import annotations

import json
import math

from hypothesis import given
from hypothesis import strategies as st

from selpres.storage import to_json, write_json

scalars = st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=5)
values = st.recursive(
    scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=4)
)


@given(values)
def test_to_json_reads_back_as_json_dumps_does(value):
    assert json.loads(to_json(value)) == json.loads(json.dumps(value))


def test_lists_of_numbers_stay_on_one_line_and_non_finite_values_survive(tmp_path):
    record = {"curves": [{"epoch": 0, "heldout_rms_nm": [0.5, None, math.nan, math.inf]}], "n": {"a": []}}
    write_json(tmp_path / "r.json", record)
    text = (tmp_path / "r.json").read_text()
    assert '"heldout_rms_nm": [0.5, null, NaN, Infinity]' in text.splitlines()[4]
    back = json.loads(text)
    assert back["curves"][0]["heldout_rms_nm"][:2] == [0.5, None] and math.isnan(back["curves"][0]["heldout_rms_nm"][2])
    assert back["n"] == {"a": []} and text.endswith("}\n")


def test_keys_that_are_not_strings_become_what_json_dumps_makes_of_them():
    value = {7: "a", 2.5: "b", True: "c", None: "d"}
    assert json.loads(to_json(value)) == json.loads(json.dumps(value))


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(2**63), 2**64 - 1), min_size=1))
def test_lists_of_numbers_read_back_exactly(vals):
    """Number lists take orjson's shortest round-trip text: every value reads back to the same double/int."""
    back = json.loads(to_json(vals))
    assert back == vals and [type(v) for v in back] == [type(v) for v in vals]


def test_number_lists_that_orjson_cannot_write_exactly_go_through_json():
    """orjson would write NaN/inf as null and refuses ints beyond 64 bits: those lists go through json; a
    plain list of floats goes through orjson (its compact text)."""
    assert to_json([0.5, 1e-05, 3e-12]) == "[0.5,0.00001,3e-12]"
    assert to_json([0.5, math.nan]) == "[0.5, NaN]" and to_json([1e308, 1e308]) == "[1e+308, 1e+308]"
    assert to_json([2**70, 1]) == f"[{2**70}, 1]" and to_json([-math.inf]) == "[-Infinity]"
