"""tools.pole_clutter: the poles stage's weather report, counted against the truth's weather flags."""

from __future__ import annotations

import csv

import pytest

from tools import pole_clutter


@pytest.mark.slow
def test_the_report_counts_weather_poles_by_the_truth_and_the_clear_twin_has_none(tmp_path, capsys):
    code = pole_clutter.main(["--seeds", "7", "--families", "city", "--conditions", "dense-fog,clear",
                              "--frames", "2", "--out", str(tmp_path)])
    assert code == 0
    rows = {r["condition"]: {k: int(v) for k, v in r.items() if k not in ("family", "sensor", "condition")}
            for r in csv.DictReader(open(tmp_path / "pole_clutter.csv"))}
    fog, clear = rows["dense-fog"], rows["clear"]
    assert clear["weather"] == clear["isolated_weather"] == clear["confirmed_weather"] == 0
    assert clear["cluttered"] == 0 and fog["cluttered"] == 2  # the filter engages in the fog only
    assert clear["isolated_structure"] == clear["structure"]
    assert fog["weather"] > fog["structure"] > 0  # the clutter the stage must survive
    assert fog["isolated_weather"] < 0.05 * fog["weather"]
    assert fog["isolated_structure"] <= fog["structure"]
    # the map's target without the filter is mostly weather; with it, mostly structure
    assert fog["target_weather"] > fog["target_structure"]
    assert fog["confirmed_weather"] < fog["confirmed_structure"]
    assert "| dense-fog |" in capsys.readouterr().out


def test_bad_arguments_say_what_is_wrong(tmp_path, capsys):
    with pytest.raises(SystemExit):
        pole_clutter.main(["--frames", "0", "--out", str(tmp_path)])
    assert "--frames must be at least 1" in capsys.readouterr().err
    assert pole_clutter.main(["--families", "atlantis", "--out", str(tmp_path)]) == 2
    assert "unknown family 'atlantis'" in capsys.readouterr().err
