"""The report a person opens: one self-contained ``report.html`` per estimate, and an
``index.html`` over a batch.

In: what ``result.json`` says of an estimate (the record), a :class:`ReportScene` (the food
mesh, the observed cloud and the completion network's points, in metres) and the report's PNG
pictures. Out: HTML text: the volume with its trust flag and reasons, a strip of frames with
the food masks' outlines, the clouds and the mesh in an interactive 3D viewer (three.js,
bundled in :file:`report_assets/viewer.min.js` with its licence), the per-stage times and the
warnings. Everything is inlined (script, data, pictures) and the page's Content-Security-Policy
forbids every request, so it opens offline in any browser and can never reach the network.

:func:`batch_index_html` turns a batch table (:mod:`volec.batch`) into a sortable page linking
every capture's report. :func:`write_report_html` and :func:`write_batch_index` write them
atomically.
"""

from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import trimesh

from volec.io import write_text_atomic
from volec.pointcloud import PREDICTED_COLOUR, PointCloud

CONTENT_SECURITY_POLICY = ("default-src 'none'; script-src 'unsafe-inline'; "
                           "style-src 'unsafe-inline'; img-src data:")
"""No fetch, image, font or frame from anywhere: the page is complete as it is."""



@dataclass(frozen=True)
class ReportConfig:
    """What the 3D view holds."""

    max_points: int = 60_000
    """Points of each cloud shown at most (an even random sample beyond that)."""
    max_faces: int = 200_000
    """Mesh triangles shown at most (a quadric decimation beyond that, for the view only:
    the volume is the full mesh's)."""
    point_size_m: float = 0.0012
    """Drawn size of a point, metres."""
    predicted_size_factor: float = 2.5
    """The network's points are drawn this much larger, so that the few of them stand out."""
    seed: int = 0
    """Seed of the point sample."""


@dataclass(frozen=True)
class ReportScene:
    """The geometry an estimate's 3D view shows, in the capture's world frame (metres)."""

    mesh: trimesh.Trimesh
    observed: PointCloud
    """The measured points: the masked food cloud, then the rim points the masks' outlines
    placed (:mod:`volec.rims`, cyan)."""
    predicted_xyz: np.ndarray
    """(M, 3) the completion network's points ((0, 3) without completion)."""
    up: np.ndarray
    """(3,) the world's up direction (the support plane's normal)."""


def viewer_script() -> str:
    """The bundled viewer (three.js and volec's viewer code), to inline."""
    return resources.files("volec").joinpath("report_assets/viewer.min.js").read_text("utf-8")


def _b64(array: np.ndarray, dtype: type) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _sample(n: int, most: int, rng: np.random.Generator) -> np.ndarray:
    return np.arange(n) if n <= most else np.sort(rng.choice(n, most, replace=False))


def shown_mesh(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """``mesh``, decimated to at most ``max_faces`` triangles for the view."""
    if len(mesh.faces) <= max_faces:
        return mesh
    import open3d as o3d

    o3 = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(mesh.vertices),
                                   o3d.utility.Vector3iVector(mesh.faces))
    small = o3.simplify_quadric_decimation(target_number_of_triangles=max_faces)
    return trimesh.Trimesh(np.asarray(small.vertices), np.asarray(small.triangles), process=False)


def viewer_data(scene: ReportScene, cfg: ReportConfig) -> dict[str, Any]:
    """The 3D view's data (see :file:`report_assets/viewer_src.js`): the mesh and the two
    clouds as base64 arrays, sampled down to ``cfg``'s limits."""
    rng = np.random.default_rng(cfg.seed)
    mesh = shown_mesh(scene.mesh, cfg.max_faces)
    observed = scene.observed.subset(_sample(len(scene.observed), cfg.max_points, rng))
    predicted = np.asarray(scene.predicted_xyz, float).reshape(-1, 3)
    predicted = predicted[_sample(len(predicted), cfg.max_points, rng)]
    layers = [{"name": "observed", "kind": "points", "positions": _b64(observed.xyz, np.float32),
               "size_m": cfg.point_size_m, "visible": False, "count": len(observed),
               "of": len(scene.observed)}]
    if observed.rgb is not None:
        layers[0]["colors"] = _b64(observed.rgb, np.uint8)
    else:
        layers[0]["color"] = "#4a7ab5"
    if len(predicted):
        layers.append({"name": "predicted", "kind": "points", "color": PREDICTED_COLOUR,
                       "positions": _b64(predicted, np.float32),
                       "size_m": cfg.predicted_size_factor * cfg.point_size_m,
                       "visible": False, "count": len(predicted),
                       "of": len(scene.predicted_xyz)})
    return {"up": [float(v) for v in scene.up],
            "mesh": {"positions": _b64(mesh.vertices, np.float32),
                     "indices": _b64(mesh.faces, np.uint32), "faces": len(mesh.faces)},
            "layers": layers}


def png_data_uri(png: bytes) -> str:
    """A PNG as a ``data:`` URI (the page may load nothing else)."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _json_for_script(data: Any) -> str:
    """JSON that cannot end the ``<script>`` element it sits in."""
    return json.dumps(data, separators=(",", ":")).replace("</", "<\\/")


def _trust_html(record: dict[str, Any]) -> str:
    if record["trusted"]:
        return '<p class="trust ok">Trusted: no reason found to doubt this volume.</p>'
    items = "".join(f"<li><code>{html.escape(r['code'])}</code>: {html.escape(r['message'])}</li>"
                    for r in record["reasons"])
    return f'<div class="trust bad"><p>Not trusted, because:</p><ul>{items}</ul></div>'


def bounds_sentence(record: dict[str, Any]) -> str:
    """What the volume bounds of a ``result.json`` record say, in one sentence (both reports
    use it)."""
    low, high = record["volume_bounds_ml"]
    more = " or more" if record.get("high_open") else ""
    return (f"Between {low:.1f} and {high:.1f} mL{more} from what the cameras saw: the estimate "
            "with the space no camera constrained taken as empty, and as food. "
            f"{100 * record['unknown_share']:.0f} % of the estimate lies in that space, where "
            "only the shape prior decides." + scale_sentence(record) + measured_sentence(record))


def scale_sentence(record: dict[str, Any]) -> str:
    """The bounds widened by the metric scale's uncertainty (``volume_interval_ml``), as a
    sentence that starts with a space (empty for a ``result.json`` record made before volec
    reported it)."""
    if "volume_interval_ml" not in record:
        return ""
    std_pct = record["scale_std_pct"]
    low, high = record["volume_interval_ml"]
    if std_pct is None or high is None:
        return (" The metric scale's uncertainty is not known (the poses' metres are not "
                "the phone's AR tracking's, or they do not bound it), so it is not in these "
                "bounds.")
    sigmas = record["config"]["scale_sigmas"]
    more = " or more" if record.get("high_open") else ""
    return (f" With the metric scale's uncertainty as well ({sigmas:g} standard deviations of "
            f"{std_pct:.2f} % in length, from the AR poses' drift), between {low:.1f} and "
            f"{high:.1f} mL{more}.")


def measured_sentence(record: dict[str, Any]) -> str:
    """How much of the surface was measured (within the record's config's
    ``measured_reach_m``), as a sentence that starts with a space (empty for a
    ``result.json`` record made before volec reported it). The bounds take the measured
    surface as right."""
    share = record.get("measured_surface_share")
    if share is None:
        return ""
    reach_mm = 1000 * record["config"]["measured_reach_m"]
    return (f" {100 * share:.0f} % of the mesh's surface lies within {reach_mm:g} mm of a "
            "measured point; the bounds take that surface as right.")


def _bounds_html(record: dict[str, Any]) -> str:
    if "volume_bounds_ml" not in record:
        return ""
    return f'<p class="bounds">{html.escape(bounds_sentence(record))}</p>'


def _facts_html(record: dict[str, Any]) -> str:
    frames = record["frames"]
    mesh = record["mesh"]
    rows = [
        ("capture", f"<code>{html.escape(str(record['capture']))}</code>"),
        ("frames used", f"{frames['registered']} of {frames['total']}"),
        ("orbit coverage", f"{record.get('orbit_coverage_deg', 0):.0f} degrees"),
        ("scale", html.escape(str(record["scale"]["source"]))),
        ("food masks", html.escape(str(record["masks"]["source"]))),
        ("completion", "used" if record["completion_used"] else "not used"),
        ("mesh", f"{mesh['faces']} faces, watertight: <code>mesh.ply</code>, "
                 "<code>mesh.glb</code>"),
        ("support plane", "found" if record["support_plane"] else "not found"),
        ("volec", html.escape(str(record["volec_version"]))),
    ]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    return f'<table class="facts">{body}</table>'


def _seconds_html(seconds: dict[str, float]) -> str:
    body = "".join(f"<tr><td>{html.escape(k.removesuffix('_s'))}</td>"
                   f"<td class='num'>{v:.1f}</td></tr>" for k, v in seconds.items())
    return f"<table><tr><th>stage</th><th>seconds</th></tr>{body}</table>"


def _list_html(items: list[str]) -> str:
    if not items:
        return "<p>none</p>"
    return "<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in items) + "</ul>"


def _layer_boxes(data: dict[str, Any]) -> str:
    labels = {"observed": "observed points (their colours; cyan: placed by the masks' "
                          "outlines)",
              "predicted": f'<span style="color:{PREDICTED_COLOUR}">&#9679;</span> '
                           "the shape priors' points (completion; the underside's mirror)"}
    boxes = ['<label><input type="checkbox" data-layer="mesh" checked> mesh</label>',
             '<label><input type="checkbox" id="volec-see-through"> see-through mesh</label>']
    for layer in data["layers"]:
        shown = (f" ({layer['count']} of {layer['of']})" if layer["count"] < layer["of"]
                 else f" ({layer['count']})")
        boxes.append(f'<label><input type="checkbox" data-layer="{layer["name"]}"> '
                     f"{labels[layer['name']]}{shown}</label>")
    boxes.append('<label><input type="checkbox" id="volec-rotate" checked> rotate</label>')
    return " ".join(boxes)


STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:0 auto;max-width:1100px;
padding:1em 1.5em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}.volume{font-size:2.2em;font-weight:600;margin:.2em 0}
.trust{padding:.5em .9em;border-radius:6px}.ok{background:#e3f4e1}.bad{background:#fde8e4}
.trust ul{margin:.2em 0}table{border-collapse:collapse;margin:.5em 0}
td,th{padding:.2em .8em;text-align:left;border-bottom:1px solid #ddd}.num{text-align:right}
#volec-viewer{width:100%;height:520px;border:1px solid #ccc;border-radius:6px;background:#f4f4f2}
.controls label{margin-right:1em;white-space:nowrap}img{max-width:100%}
.facts th{font-weight:500;color:#555}
"""


def report_html(record: dict[str, Any], scene: ReportScene, pictures: dict[str, bytes],
                cfg: ReportConfig | None = None) -> str:
    """The whole report page of one estimate. ``pictures``: PNG bytes by name (``masks``: the
    frames with the masks' outlines; the others, views of the clouds and mesh)."""
    cfg = cfg or ReportConfig()
    data = viewer_data(scene, cfg)
    completion = "with" if record["completion_used"] else "without"
    masks = pictures.get("masks")
    strip = ("" if masks is None else
             f'<h2>The capture</h2><p>Frames with the outlines of the food masks used '
             f'({html.escape(str(record["masks"]["source"]))}).</p>'
             f'<img alt="frames with mask outlines" src="{png_data_uri(masks)}">')
    views = "".join(f'<figure><img alt="{html.escape(name)}" src="{png_data_uri(png)}">'
                    f"<figcaption>seen from {html.escape(name)}</figcaption></figure>"
                    for name, png in pictures.items() if name != "masks")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>volec: {record['volume_ml']:.1f} mL</title><style>{STYLE}</style></head>
<body>
<h1>volec estimate</h1>
<p class="volume">{record['volume_ml']:.1f} mL</p>
<p>{completion} completion</p>
{_bounds_html(record)}
{_trust_html(record)}
{_facts_html(record)}
<h2>Warnings</h2>{_list_html(record['warnings'])}
{strip}
<h2>In 3D</h2>
<p>Drag to turn, scroll to zoom, right-drag to move. Metres, the capture's world frame.</p>
<div id="volec-viewer"></div>
<p class="controls">{_layer_boxes(data)}</p>
<h2>Pictures</h2>{views}
<h2>Wall time per stage</h2>{_seconds_html(record['stage_seconds'])}
<script type="application/json" id="volec-data">{_json_for_script(data)}</script>
<script>{viewer_script()}</script>
<script>
window.VolecViewer.start(document.getElementById('volec-viewer'),
  JSON.parse(document.getElementById('volec-data').textContent));
</script>
</body></html>
"""


def write_report_html(path: Path, record: dict[str, Any], scene: ReportScene,
                      pictures: dict[str, bytes], cfg: ReportConfig | None = None) -> Path:
    """Write :func:`report_html` to ``path`` atomically."""
    write_text_atomic(path, report_html(record, scene, pictures, cfg))
    return path


def batch_index_html(table: pd.DataFrame, reports: dict[str, str]) -> str:
    """A page with the batch ``table`` (one row a capture), sortable by any column (click its
    header), each capture linking to its report (``reports``: capture -> relative path)."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in table.columns)
    rows = []
    for _, row in table.iterrows():
        cells = []
        for column in table.columns:
            value = row[column]
            text = "" if pd.isna(value) else str(value)
            cell = html.escape(text)
            if column == "capture" and text in reports:
                cell = f'<a href="{html.escape(reports[text])}">{cell}</a>'
            sort_key = value if isinstance(value, int | float) and not pd.isna(value) else text
            cells.append(f'<td data-sort="{html.escape(str(sort_key))}">{cell}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">
<title>volec batch: {len(table)} captures</title><style>{STYLE}
th{{cursor:pointer;user-select:none}}</style></head>
<body><h1>volec batch</h1><p>{len(table)} captures. Click a column's header to sort by it;
a capture's name opens its report.</p>
<table id="batch"><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>
<script>
document.querySelectorAll('#batch th').forEach((th, column) => {{
  th.addEventListener('click', () => {{
    const body = document.querySelector('#batch tbody');
    const up = th.dataset.order !== 'up';
    th.dataset.order = up ? 'up' : 'down';
    const key = (tr) => tr.children[column].dataset.sort;
    const rows = Array.from(body.rows).sort((a, b) => {{
      const x = key(a), y = key(b), nx = parseFloat(x), ny = parseFloat(y);
      const order = (!isNaN(nx) && !isNaN(ny)) ? nx - ny : x.localeCompare(y);
      return up ? order : -order;
    }});
    rows.forEach((tr) => body.appendChild(tr));
  }});
}});
</script></body></html>
"""


def write_batch_index(path: Path, table: pd.DataFrame, reports: dict[str, str]) -> Path:
    """Write :func:`batch_index_html` to ``path`` atomically."""
    write_text_atomic(path, batch_index_html(table, reports))
    return path
