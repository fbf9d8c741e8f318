"""The code location's definitions refuse what cannot run."""


import pytest


def test_tables_for_unknown_data_sets_are_refused(tmp_path):
    from pwa_pipeline.orchestration.definitions import build_definitions

    path = tmp_path / "hp.toml"
    path.write_text("[a.hure_vasak]\n[a.kuka_robto]\n")
    with pytest.raises(ValueError, match=r"unknown data set\(s\) \['kuka_robto'\]"):
        build_definitions(path)

