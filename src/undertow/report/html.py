"""One self-contained HTML report page: tables, figures, a 3D map viewer, config and versions.

The page needs no network and no files next to it: the markdown tables are converted here (a
tiny converter for headings, paragraphs, bullet lists and pipe tables), figures are embedded as
base64 ``data:`` URIs, and the 3D view is a small inline vanilla-JS canvas viewer whose points
(map coloured by distance to the ground truth, ground truth grey; ~25k in total) are embedded as
JSON. Written atomically.
"""

from __future__ import annotations

import base64
import html
import json
import math
import re
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .._util.atomic import atomic_path
from ..errors import DataError

VIEWER_POINTS = 25_000
MAP_POINTS_MAX = 15_000
# blue (close to the ground truth) -> red (far), sampled from the "turbo" colour map
PALETTE = ("#30123b", "#4662d7", "#36aaf9", "#1ae4b6", "#72fe5e",
           "#c8ef34", "#faba39", "#f66b19", "#cb2a04", "#7a0403")  # fmt: skip


# --- markdown ---------------------------------------------------------------------------------


def _inline(text: str) -> str:
    """Escape, then `code` and **bold**."""
    out = html.escape(text.strip(), quote=False)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out)


def _cells(line: str) -> list[str]:
    line = line.strip()
    if line.startswith("|"):
        line = line[1:]
    if line.endswith("|"):
        line = line[:-1]
    return [c.strip() for c in line.split("|")]


_BULLET = re.compile(r"^\s*[-*]\s+")
_SEPARATOR = re.compile(r"^\s*\|?\s*:?-+:?\s*(\|\s*:?-+:?\s*)*\|?\s*$")


def _table(lines: list[str]) -> str:
    header = _cells(lines[0])
    align = []
    for spec in _cells(lines[1]):
        left, right = spec.startswith(":"), spec.endswith(":")
        align.append("center" if left and right else "right" if right else "left")
    align += ["left"] * (len(header) - len(align))

    def row(cells: list[str], tag: str) -> str:
        cells = cells + [""] * (len(header) - len(cells))
        return "<tr>" + "".join(
            f'<{tag} style="text-align:{a}">{_inline(c)}</{tag}>'
            for c, a in zip(cells[: len(header)], align, strict=False)
        ) + "</tr>"  # fmt: skip

    body = "\n".join(row(_cells(line), "td") for line in lines[2:])
    return (f'<div class="table-wrap"><table>\n<thead>{row(header, "th")}</thead>\n'
            f"<tbody>\n{body}\n</tbody></table></div>")  # fmt: skip


def markdown_to_html(text: str) -> str:
    """Headings (#..######), paragraphs, '-'/'*' bullet lists and pipe tables to HTML."""
    blocks, current = [], []
    for line in text.splitlines():
        if line.strip():
            current.append(line.rstrip())
        elif current:
            blocks.append(current)
            current = []
    if current:
        blocks.append(current)
    out = []
    for block in blocks:
        i = 0
        while i < len(block):
            line = block[i]
            heading = re.match(r"^(#{1,6})\s+(.*)$", line)
            if heading:
                level = len(heading.group(1))
                out.append(f"<h{level}>{_inline(heading.group(2))}</h{level}>")
                i += 1
            elif (
                line.lstrip().startswith("|")
                and i + 1 < len(block)
                and _SEPARATOR.match(block[i + 1])
            ):
                j = i + 2
                while j < len(block) and block[j].lstrip().startswith("|"):
                    j += 1
                out.append(_table(block[i:j]))
                i = j
            elif _BULLET.match(line):
                items = []
                while i < len(block) and _BULLET.match(block[i]):
                    items.append(f"<li>{_inline(_BULLET.sub('', block[i]))}</li>")
                    i += 1
                out.append("<ul>" + "".join(items) + "</ul>")
            else:
                para = []
                while i < len(block) and not (
                    re.match(r"^(#{1,6})\s+|^\s*[-*]\s+|^\s*\|", block[i])
                ):
                    para.append(block[i].strip())
                    i += 1
                if not para:  # a stray '|' line that is not a table
                    para, i = [block[i]], i + 1
                out.append(f"<p>{_inline(' '.join(para))}</p>")
    return "\n".join(out)


# --- data -------------------------------------------------------------------------------------


def _plain(value):
    """JSON-able copy: numpy to Python, non-finite floats to None, unknown objects to str."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, Path):
        return str(value)
    return str(value)


def _script_json(value) -> str:
    """JSON safe inside <script> (no '<' characters, so no '</script>')."""
    return json.dumps(_plain(value), separators=(",", ":")).replace("<", "\\u003c")


def _cloud(name: str, points) -> np.ndarray:
    arr = np.asarray(points if points is not None else np.zeros((0, 3)), dtype=float)
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise DataError(f"{name}: shape {arr.shape}, expected (N, 3)")
    return arr[np.all(np.isfinite(arr), axis=1)]


def _pick(points: np.ndarray, n: int, seed: int) -> np.ndarray:
    if len(points) <= n:
        return points
    return points[np.sort(np.random.default_rng(seed).choice(len(points), n, replace=False))]


def viewer_data(map_points, ground_truth_points, n_total: int = VIEWER_POINTS) -> dict:
    """The 3D viewer's payload: subsampled, centred coordinates (mm precision, z DOWN as given),
    the map's colour bin (distance to the ground truth, :data:`PALETTE`) and the bin edges."""
    mp = _cloud("map_points", map_points)
    gt = _cloud("ground_truth_points", ground_truth_points)
    mp = _pick(mp, min(MAP_POINTS_MAX, n_total), seed=1)
    gt = _pick(gt, max(n_total - len(mp), 0), seed=2)
    both = np.concatenate([mp, gt]) if len(mp) + len(gt) else np.zeros((1, 3))
    centre = 0.5 * (both.min(axis=0) + both.max(axis=0))
    if len(mp) and len(gt):
        dist = cKDTree(gt).query(mp, k=1)[0]
        top = max(float(np.percentile(dist, 95)), 2.0 * float(np.median(dist)), 1e-3)
    else:
        dist, top = np.zeros(len(mp)), 1.0
    bins = np.clip((dist / top * len(PALETTE)).astype(int), 0, len(PALETTE) - 1)
    return {
        "centre": np.round(centre, 3).tolist(),
        "map": np.round(mp - centre, 3).ravel().tolist(),
        "map_bin": bins.tolist(),
        "gt": np.round(gt - centre, 3).ravel().tolist(),
        "palette": list(PALETTE),
        "distance_max_m": round(top, 4),
    }


# --- page -------------------------------------------------------------------------------------

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222;
background:#fafafa;line-height:1.45}
main{max-width:1150px;margin:0 auto;padding:1.5em 2em 4em}
h1{font-size:1.7em;border-bottom:2px solid #3465a4;padding-bottom:.3em}
h2{font-size:1.35em;margin-top:2em;border-bottom:1px solid #ccc}h3{font-size:1.1em}
nav a{margin-right:1em;color:#3465a4}
.table-wrap{overflow-x:auto;margin:.6em 0 1.2em}
table{border-collapse:collapse;font-size:.86em;background:#fff}
th,td{border:1px solid #d0d0d0;padding:.3em .6em;white-space:nowrap}
th{background:#eef2f8}tbody tr:nth-child(even){background:#f6f6f6}
figure{margin:1.5em 0;background:#fff;border:1px solid #ddd;padding:.8em}
figure img{max-width:100%;height:auto;display:block;margin:0 auto}
figcaption{font-size:.9em;color:#444;margin-top:.5em}
pre{background:#f0f0f0;border:1px solid #ddd;padding:.8em;overflow-x:auto;font-size:.82em}
code{background:#f0f0f0;padding:0 .2em}
#viewer{width:100%;height:560px;background:#fff;border:1px solid #ccc;cursor:grab;display:block}
.controls{font-size:.88em;margin:.4em 0;display:flex;gap:1.2em;align-items:center;flex-wrap:wrap}
.bar{display:inline-block;width:180px;height:12px;vertical-align:middle;border:1px solid #999}
ul.notes li{margin:.3em 0}
"""

_VIEWER_JS = """
(function(){
const D=JSON.parse(document.getElementById('viewer-data').textContent);
const cv=document.getElementById('viewer'),ctx=cv.getContext('2d');
const ex=document.getElementById('exaggeration'),exv=document.getElementById('exaggeration-value');
let yaw=-0.6,pitch=0.5,zoom=1,panX=0,panY=0,drag=null;
let ext=1e-6;for(const a of [D.map,D.gt])for(let i=0;i<a.length;i+=3)
 ext=Math.max(ext,Math.abs(a[i]),Math.abs(a[i+1]));
const byBin=D.palette.map(()=>[]);
for(let k=0;k<D.map_bin.length;k++)byBin[D.map_bin[k]].push(k*3);
const gtIdx=[];for(let i=0;i<D.gt.length;i+=3)gtIdx.push(i);
function draw(){
 const dpr=window.devicePixelRatio||1,w=cv.clientWidth,h=cv.clientHeight;
 if(cv.width!==Math.round(w*dpr)||cv.height!==Math.round(h*dpr)){
  cv.width=Math.round(w*dpr);cv.height=Math.round(h*dpr);}
 ctx.setTransform(dpr,0,0,dpr,0,0);ctx.clearRect(0,0,w,h);
 const s=0.48*Math.min(w,h)/ext*zoom,e=parseFloat(ex.value),cy=Math.cos(yaw),sy=Math.sin(yaw),
  cp=Math.cos(pitch),sp=Math.sin(pitch),ox=w/2+panX,oy=h/2+panY;
 function pass(a,idx,size){for(const i of idx){
  const x=a[i],y=a[i+1],up=-a[i+2]*e,xr=x*cy-y*sy,yr=x*sy+y*cy;
  ctx.fillRect(ox+s*xr-size/2,oy-s*(up*cp+yr*sp)-size/2,size,size);}}
 ctx.fillStyle='rgba(110,110,110,0.45)';pass(D.gt,gtIdx,1.5);
 for(let b=0;b<byBin.length;b++){ctx.fillStyle=D.palette[b];pass(D.map,byBin[b],2.6);}
 exv.textContent=e.toFixed(0)+'x';}
let pending=false;function redraw(){if(!pending){pending=true;
 requestAnimationFrame(()=>{pending=false;draw();});}}
cv.addEventListener('mousedown',ev=>{drag={x:ev.clientX,y:ev.clientY,pan:ev.shiftKey};
 cv.style.cursor='grabbing';});
window.addEventListener('mouseup',()=>{drag=null;cv.style.cursor='grab';});
window.addEventListener('mousemove',ev=>{if(!drag)return;
 const dx=ev.clientX-drag.x,dy=ev.clientY-drag.y;drag.x=ev.clientX;drag.y=ev.clientY;
 if(drag.pan){panX+=dx;panY+=dy;}else{yaw+=dx*0.01;
  pitch=Math.max(-1.57,Math.min(1.57,pitch+dy*0.01));}redraw();});
cv.addEventListener('wheel',ev=>{ev.preventDefault();
 zoom*=Math.exp(-ev.deltaY*0.0015);zoom=Math.max(0.2,Math.min(200,zoom));redraw();},
 {passive:false});
document.getElementById('viewer-reset').addEventListener('click',()=>{
 yaw=-0.6;pitch=0.5;zoom=1;panX=0;panY=0;redraw();});
ex.addEventListener('input',redraw);window.addEventListener('resize',redraw);draw();
})();
"""


def _figure_html(caption: str, png: Path, number: int) -> str:
    png = Path(png)
    if not png.is_file():
        raise DataError(f"write_report: figure file {png} does not exist")
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    cap = html.escape(caption)
    img = f'<img alt="{cap}" src="data:image/png;base64,{data}">'
    label = f"<strong>Figure {number}.</strong>"
    return f'<figure id="figure-{number}">{img}<figcaption>{label} {cap}</figcaption></figure>'


def _config_text(config: dict) -> str:
    plain = _plain(config)
    try:
        import yaml

        return yaml.safe_dump(plain, sort_keys=False, allow_unicode=True)
    except ImportError:  # pragma: no cover - pyyaml is a dependency
        return json.dumps(plain, indent=2)


def _viewer_html(data: dict) -> str:
    bar = "linear-gradient(to right," + ",".join(data["palette"]) + ")"
    n_map, n_gt = len(data["map"]) // 3, len(data["gt"]) // 3
    return f"""<h2 id="viewer-section">3D map viewer</h2>
<p>Map points ({n_map}) coloured by distance to the ground truth over the ground-truth scan
({n_gt} points, grey), subsampled. Drag to rotate, shift-drag to pan, wheel to zoom.</p>
<div class="controls"><span>distance 0 m <span class="bar" style="background:{bar}"></span>
{data["distance_max_m"]:.3f} m and more</span>
<label>vertical exaggeration <input id="exaggeration" type="range" min="1" max="20" step="1"
value="1"> <span id="exaggeration-value">1x</span></label>
<button id="viewer-reset" type="button">reset view</button></div>
<canvas id="viewer"></canvas>
<script type="application/json" id="viewer-data">{_script_json(data)}</script>
<script>{_VIEWER_JS}</script>"""


def write_report(
    path,
    *,
    title: str,
    tables_markdown: str,
    tables: dict,
    figures: list[tuple[str, str | Path]],
    map_points,
    ground_truth_points,
    config: dict,
    versions: dict,
    notes: list[str],
) -> Path:
    """Write one self-contained HTML page (atomic) and return its path.

    Sections: notes, tables (``tables_markdown`` converted; ``tables`` embedded as JSON for
    reference), figures (base64 PNG, in the given order with their captions), the 3D viewer
    of ``map_points`` (N, 3) over ``ground_truth_points`` (M, 3), the config (YAML) and the
    versions.
    """
    esc = html.escape
    figs = "\n".join(_figure_html(c, p, i + 1) for i, (c, p) in enumerate(figures))
    notes_html = "".join(f"<li>{_inline(n)}</li>" for n in notes) or "<li>none</li>"
    versions_rows = "".join(
        f"<tr><td>{esc(str(k))}</td><td>{esc(str(v))}</td></tr>" for k, v in versions.items()
    )
    tables_json = json.dumps(_plain(tables), indent=1)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{esc(title)}</title><style>{_CSS}</style></head>
<body><main>
<h1>{esc(title)}</h1>
<nav><a href="#notes">notes</a><a href="#tables">tables</a><a href="#figures">figures</a>
<a href="#viewer-section">3D viewer</a><a href="#config">config</a>
<a href="#versions">versions</a></nav>
<h2 id="notes">Notes</h2><ul class="notes">{notes_html}</ul>
<section id="tables"><h2>Tables</h2>
{markdown_to_html(tables_markdown)}
<details><summary>All table values (JSON)</summary><pre>{esc(tables_json)}</pre></details>
<script type="application/json" id="tables-data">{_script_json(tables)}</script>
</section>
<section id="figures"><h2>Figures</h2>
{figs}
</section>
{_viewer_html(viewer_data(map_points, ground_truth_points))}
<h2 id="config">Configuration</h2><pre>{esc(_config_text(config))}</pre>
<h2 id="versions">Versions</h2>
<div class="table-wrap"><table><thead><tr><th>package</th><th>version</th></tr></thead>
<tbody>{versions_rows}</tbody></table></div>
</main></body></html>
"""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(page, encoding="utf-8")
    return path
