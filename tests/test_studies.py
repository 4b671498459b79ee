"""The paper's studies (studies.py): specifications and their descriptions (the runs: test_cli.py)."""


def test_reproduce_metrics_name_the_vehicle_and_its_source():
    from tire_learning_env.studies import _describe, study_spec

    for study in (1, 2, 3):
        described = _describe(study_spec(study, 1.0))
        assert described["nominal_vehicle"]["Cf"] > 0 and described["true_vehicle"]["m"] > 0
        assert f"study {study}" in described["vehicle_source"]
