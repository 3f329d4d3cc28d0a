"""The README's generated parts match what generates them."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_refusals_section_is_generated_from_the_test_table():
    import importlib.util

    spec = importlib.util.spec_from_file_location("refusals_table",
                                                  ROOT / "scripts" / "refusals_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    readme = (ROOT / "README.md").read_text()
    assert module.updated_readme(readme) == readme, \
        "README.md is out of date: run .venv/bin/python scripts/refusals_table.py"
