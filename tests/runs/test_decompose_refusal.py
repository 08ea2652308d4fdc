"""``--decompose`` on a case that already holds ``processor*`` directories is refused before
anything runs: ``decomposePar -force`` would delete them, and they may be the user's."""
import hashlib

import pytest

from pbe_cfd.scene.scene import SceneError

from conftest import make_scene


def _tree(root):
    """Every file under root with the SHA-256 of its bytes."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_decompose_refuses_a_case_with_processor_directories(tmp_path):
    from pbe_cfd.runs.distributed import make_executor

    case = tmp_path / "my-bed"
    (case / "system").mkdir(parents=True)
    (case / "system" / "controlDict").write_text("FoamFile {}\n")
    (case / "processor0" / "0.5").mkdir(parents=True)
    (case / "processor0" / "0.5" / "alpha.particlesMean").write_text("the user's field\n")
    (case / "processor1").mkdir()
    before = _tree(case)
    scene = make_scene(domain={"_replace": True, "type": "openfoam", "case": str(case)},
                       initial={"_replace": True, "distribution": "monodisperse",
                                "mean_mass": 1.0e-9})
    with pytest.raises(SceneError, match=r"already decomposed.*decomposePar -force") as err:
        make_executor(scene, None, tmp_path / "out", decompose=2)
    assert err.value.key == "domain.case"
    assert _tree(case) == before                       # nothing of the case touched
    assert not (tmp_path / "out").exists()             # no output begun
