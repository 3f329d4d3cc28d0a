"""Tables and figures name the code that made them."""

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
from PIL import Image  # noqa: E402

from volec import __version__  # noqa: E402
from volec.provenance import package_digest  # noqa: E402
from volec.tables import write_table  # noqa: E402
from volec.viz import save_figure  # noqa: E402


def test_a_table_records_the_volec_version_and_source_digest(tmp_path):
    csv, md = write_table(pd.DataFrame({"item": ["apple"], "ml": [231.5]}), tmp_path / "t")
    assert pd.read_csv(csv).to_dict("list") == {"item": ["apple"], "ml": [231.5]}  # clean CSV
    footer = md.read_text().strip().splitlines()[-1]
    assert f"volec {__version__}" in footer and package_digest() in footer
    meta = json.loads((tmp_path / "t.provenance.json").read_text())
    assert meta["source_digest"] == package_digest() and meta["rows"] == 1


def test_a_figure_records_them_in_its_png_metadata(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "f.png")
    with Image.open(path) as im:
        assert im.info["Software"] == f"volec {__version__} (source {package_digest()})"
