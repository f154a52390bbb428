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
