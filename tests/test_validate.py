import json
from pathlib import Path

import numpy as np
import pytest

from glassdist.cli import main
from glassdist.scene import load_scene
from glassdist.virtual import procrustes

EXAMPLES = Path(__file__).parents[1] / "examples" / "scenes"


@pytest.mark.parametrize("angle, scale", [(0.0, 1.0), (3.0, 0.95), (-40.0, 1.2)])
def test_procrustes_recovers_rotation_and_scale(angle, scale):
    rng = np.random.default_rng(1)
    X = rng.normal(size=(500, 2))
    t = np.radians(angle)
    R = np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])  # row-vector rotation from +x towards +y
    Y = scale * X @ R + 0.3
    rot, s = procrustes(X, Y)
    assert rot == pytest.approx(angle, abs=1e-9) and s == pytest.approx(scale, rel=1e-9)
    # the rotation sign: +x mapped towards +y is positive
    rot90, _ = procrustes(np.array([[1.0, 0.0], [0.0, 1.0], [-1, 0], [0, -1]]), np.array([[0.0, 1.0], [-1.0, 0.0], [0, -1], [1, 0]]))
    assert rot90 == pytest.approx(90.0)


def _small_wavy(tmp_path):
    scene = load_scene(EXAMPLES / "wavy_slab.yaml").with_changes(
        camera={"pixels": [320, 240]},
        backdrop={"pitch_mm": 48.4, "line_width_mm": 10},
        render={"samples_per_pixel": 4, "seed": 2},
    )
    path = tmp_path / "wavy_small.json"
    path.write_text(json.dumps(scene.model_dump(mode="json")))
    return path


@pytest.mark.slow
@pytest.mark.parametrize("method", ["direct", "comparative"])
def test_validate_command_on_a_small_wavy_slab(tmp_path, method):
    out = tmp_path / "out"
    assert main(["validate", str(_small_wavy(tmp_path)), "--method", method, "--out", str(out), "--no-progress"]) == 0
    rec = json.loads((out / "validation.json").read_text())
    for name in ("phi_eff", "phi_shear", "phi_total"):
        assert 0.95 < rec["ratios"][name] < 1.05
        assert rec["correlations"][name] > 0.97
        assert rec["model_vs_exact"][name] == pytest.approx(1.0, abs=0.01)
    assert abs(rec["procrustes"]["rotation_deg"]) < 0.5
    assert rec["procrustes"]["scale"] == pytest.approx(1.0, abs=0.05)
    assert rec["method"] == method
    for f in ("distorted.png", "reference.png", "validation.png"):
        assert (out / f).stat().st_size > 0


def test_render_and_predict_commands(tmp_path):
    scene = load_scene(EXAMPLES / "wavy_slab.yaml").with_changes(
        camera={"pixels": [96, 72]}, backdrop={"pitch_mm": 96.8, "line_width_mm": 16}, render={"samples_per_pixel": 1}
    )
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(scene.model_dump(mode="json")))
    out = tmp_path / "r"
    assert main(["render", str(path), "--out", str(out), "--displacement", "--no-progress"]) == 0
    from glassdist.io import read_image

    img = read_image(out / "distorted.png")
    assert img.shape == (72, 96) and (out / "reference.png").exists()
    import cv2

    assert cv2.imread(str(out / "distorted.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint16
    assert np.load(out / "displacement_mm.npy").shape == (72, 96, 2)
    assert main(["predict", str(path), "--out", str(tmp_path / "p"), "--sigma-mm", "150"]) == 0
    pred = np.load(tmp_path / "p" / "prediction.npz")
    assert pred["displacement_mm"].shape == (72, 96, 2) and pred["phi_eff_mD"].shape == (72, 96)
    assert json.loads((tmp_path / "p" / "prediction.json").read_text())["sigma_mm"] == 150


def test_commands_reject_bad_input(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.yaml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "does not exist" in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.yaml"
    bad.write_text((EXAMPLES / "wavy_slab.yaml").read_text().replace("thickness_mm: 20", "thickness_mm: -20"))
    assert main(["predict", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "thickness_mm" in capsys.readouterr().err
