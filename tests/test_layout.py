"""tests/ mirrors the package's folders: every test module sits where the table of
scripts/test_layout.py places it (a whole-package check at tests/ root, the rest in the folder
of the layer it tests)."""
import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "test_layout.py"
_spec = importlib.util.spec_from_file_location("layout_rule", SCRIPT)
layout = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(layout)


def test_no_test_module_sits_where_the_table_does_not_place_it():
    wrong = [f"tests/{rel.as_posix()} belongs in tests/{want or '.'}" if want is not None
             else f"tests/{rel.as_posix()} has no row in RULES"
             for rel, want in layout.misplaced()]
    assert not wrong, ("run python scripts/test_layout.py --apply (or add a row to its "
                       "RULES):\n" + "\n".join(wrong))


def test_the_check_finds_a_root_module_of_a_layer_and_a_module_in_the_wrong_folder(tmp_path):
    (tmp_path / "viz").mkdir()
    for rel in ("test_layers.py", "test_cli_extra.py", "viz/test_couple_more.py",
                "viz/test_pictures_more.py", "test_unheard_of.py"):
        (tmp_path / rel).write_text("")
    found = {rel.as_posix(): want for rel, want in layout.misplaced(tmp_path)}
    assert found == {"test_cli_extra.py": "cli", "viz/test_couple_more.py": "runs",
                     "test_unheard_of.py": None}


def test_every_folder_of_the_table_is_a_folder_of_the_package():
    package = SCRIPT.parents[1] / "pbe_cfd"
    for _, folder in layout.RULES:
        if folder and folder != "cli":   # the CLI is pbe_cfd/cli.py
            assert (package / folder).is_dir(), folder
