"""The README's three-form table (twin.app.firmware_forms): it is docs/firmware/forms.json rendered, the JSON is
what the comparison computes now, and the single-cause runs stand for what they say (the card set to the
board's input grid reads exactly what the firmware reads)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from avr_images import example_image

from twin.app.firmware_forms import board_input_grid, compare, render
from twin.daq import adc_quantize_v
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parents[1]
FORMS = ROOT / "docs" / "firmware" / "forms.json"


@pytest.mark.quick
def test_the_readme_table_is_the_json_rendered() -> None:
    text = (ROOT / "docs" / "validation" / "firmware.md").read_text()  # the manual's page of the table
    block = re.search(r"<!-- firmware-forms -->\n(.*?)<!-- /firmware-forms -->", text, re.S)
    assert block is not None
    rendered = render(json.loads(FORMS.read_text()))
    assert block[1] == rendered == (FORMS.parent / "forms.md").read_text()


@pytest.mark.quick
def test_the_card_on_the_boards_input_grid_reads_what_the_firmware_reads() -> None:
    """The firmware's reading of a signal v: the count ⌊(2.5 + 0.5·v)·1024/5⌋ taken back through the front end at
    its bin's centre (examples/avr/rig_io.h), computed here from mcu_io; the card with ``board_input_grid``
    reads the same volts, to the bit, over ±5 V."""
    p = Parameters()
    io = p.mcu_io
    v = np.random.default_rng(3).uniform(-4.99, 4.99, 200_000)
    count = np.floor((io.input_offset_v + io.input_gain_v_per_v * v) * 2**io.adc_bits / io.adc_reference_v)
    firmware = (
        (count + 0.5) * io.adc_reference_v / 2**io.adc_bits - io.input_offset_v
    ) / io.input_gain_v_per_v
    card = adc_quantize_v(v, p.with_overrides(board_input_grid(p)).daq)
    assert np.array_equal(card, firmware)


@pytest.mark.study  # recomputes a published study's JSON (half a minute; the run's time)
def test_the_comparison_recomputes_the_published_json(tmp_path: Path) -> None:
    """The three forms, the single-cause runs and the precision replay from the same starts and seeds give the
    published records bit for bit (the validation batteries, 4 minutes, are the script's alone); the firmware's
    float replay equals its words in every run; the C client's records are the Python form's."""
    from test_c_controller import build_bb_sf

    published = json.loads(FORMS.read_text())
    elf = example_image(tmp_path)
    got = compare(elf, build_bb_sf(tmp_path), duration_s=published["settings"]["duration_s"], workers=1)
    for mine, theirs in zip(got["starts"], published["starts"], strict=True):
        assert json.dumps(mine["forms"], sort_keys=True) == json.dumps(theirs["forms"], sort_keys=True)
        assert mine["precision"] == theirs["precision"] and mine["precision"]["float_equal"]
        assert mine["forms"]["c"] == mine["forms"]["python"]
    assert got["delay_s"] == published["delay_s"] and got["resolution_v"] == published["resolution_v"]
