"""Episode recording (rendering.py); an env's own rgb_array frames: test_highway.py."""


def test_episode_saved_as_gif(tmp_path):
    from PIL import Image

    from tire_learning_env.rendering import record_episode

    out = record_episode("TireLearning-Highway-v0", tmp_path / "ep.gif", seconds=0.5, seed=1, config={"vehicles_count": 5})
    assert out["frames"] == 11
    with Image.open(tmp_path / "ep.gif") as gif:
        assert gif.n_frames == 11 and gif.size == (600, 150)
