"""tools.pole_clutter: the poles stage's weather report, counted against the truth's weather flags."""

from __future__ import annotations

import csv

import pytest

from odometry.poles import CLUTTERED_PER_BEAM
from tools import pole_clutter


@pytest.mark.slow
def test_the_report_counts_weather_poles_by_the_truth_and_the_clear_twin_has_none(tmp_path, capsys):
    code = pole_clutter.main(["--seeds", "7", "--families", "city", "--conditions", "dense-fog,clear",
                              "--frames", "2", "--out", str(tmp_path)])
    assert code == 0
    rows = {r["condition"]: {k: float(v) for k, v in r.items() if k not in ("family", "sensor", "condition")}
            for r in csv.DictReader(open(tmp_path / "pole_clutter.csv"))}
    fog, clear = rows["dense-fog"], rows["clear"]
    assert clear["weather"] == clear["isolated_weather"] == clear["confirmed_weather"] == 0
    assert clear["cluttered"] == 0 and fog["cluttered"] == 2  # the filter engages in the fog only
    # the gate's statistic (crowded one-return poles per 1000 beams) on both sides of its threshold
    assert clear["per_1000_beams_max"] < 1000 * CLUTTERED_PER_BEAM < fog["per_1000_beams_min"]
    assert clear["isolated_structure"] == clear["structure"]
    assert fog["weather"] > fog["structure"] > 0  # the clutter the stage must survive
    assert fog["isolated_weather"] < 0.05 * fog["weather"]
    assert fog["isolated_structure"] <= fog["structure"]
    # the map's target without the filter is mostly weather; with it, mostly structure
    assert fog["target_weather"] > fog["target_structure"]
    assert fog["confirmed_weather"] < fog["confirmed_structure"]
    # the stages before the poles, labelled by the truth: none in clear air; in fog the ICP's filters keep
    # less of the weather than the clean returns hold (clutter has no plane)
    assert clear["clean_weather"] == clear["icp_weather"] == clear["mapped_weather"] == 0
    assert fog["clean_weather"] > 0 and fog["icp"] > 0
    assert fog["icp_weather"] / fog["icp"] < fog["clean_weather"] / fog["clean"]
    assert "| dense-fog |" in capsys.readouterr().out


def test_bad_arguments_say_what_is_wrong(tmp_path, capsys):
    with pytest.raises(SystemExit):
        pole_clutter.main(["--frames", "0", "--out", str(tmp_path)])
    assert "--frames must be at least 1" in capsys.readouterr().err
    assert pole_clutter.main(["--families", "atlantis", "--out", str(tmp_path)]) == 2
    assert "unknown family 'atlantis'" in capsys.readouterr().err


def test_the_real_excerpts_are_reported_and_not_cluttered(real_data, tmp_path, capsys):
    code = pole_clutter.main(["--families", "city", "--conditions", "clear", "--seeds", "7", "--frames", "1",
                              "--real", f"{real_data / 'hdl32-pair'}=hdl32e", "--out", str(tmp_path)])
    assert code == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("| real: hdl32-pair"))
    scans, cluttered = (int(v) for v in line.split("|")[2:4])
    assert (scans, cluttered) == (2, 0)
    with pytest.raises(SystemExit):
        pole_clutter.main(["--real", str(tmp_path / "nowhere"), "--out", str(tmp_path)])
    assert "expected FOLDER=SENSOR" in capsys.readouterr().err
