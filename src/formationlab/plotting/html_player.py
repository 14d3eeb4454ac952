"""The HTML animation of a run in the plane as a page that draws the states itself.

The page holds the saved states the animation shows (positions rounded to 0.1 mm, the
times, the graph's edges, the diameters and the robots' colours of
:func:`~.colors.robot_colors`) and a small script that draws each frame on a canvas:
the trails, the edges, the robots as discs of their diameters with their numbers, a
scale bar in metres and the time. It starts playing when opened and can be paused and
scrubbed. A few hundred kilobytes where a player of embedded PNG frames takes megabytes.
"""

from __future__ import annotations

import html
import json
from typing import Any

import numpy as np
from matplotlib.colors import to_hex
from numpy.typing import ArrayLike

from .colors import robot_colors

__all__ = ["player_page"]

_SCRIPT = """
const D = JSON.parse(document.getElementById("states").textContent);
const cv = document.getElementById("view"), cx = cv.getContext("2d");
const slider = document.getElementById("frame"), button = document.getElementById("play");
const n = D.diameters.length, W = cv.width, H = cv.height, pad = 30;
let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
for (const s of D.q) for (const p of s) for (let a = 0; a < 2; a++) {
  lo[a] = Math.min(lo[a], p[a]); hi[a] = Math.max(hi[a], p[a]);
}
const r = Math.max(...D.diameters) / 2;
lo = lo.map(v => v - r); hi = hi.map(v => v + r);
const k = Math.min((W - 2 * pad) / (hi[0] - lo[0] || 1), (H - 2 * pad) / (hi[1] - lo[1] || 1));
const X = x => pad + (x - lo[0]) * k, Y = y => H - pad - (y - lo[1]) * k;
function bar() {
  const m = Math.pow(10, Math.floor(Math.log10((hi[0] - lo[0]) / 4)));
  const len = [5, 2, 1].map(f => f * m).find(l => l * k < (W - 2 * pad) / 3) || m;
  cx.strokeStyle = "#000"; cx.lineWidth = 2; cx.beginPath();
  cx.moveTo(pad, H - 10); cx.lineTo(pad + len * k, H - 10); cx.stroke();
  cx.fillStyle = "#000"; cx.fillText(`${len} m`, pad + len * k + 6, H - 6);
}
function draw(f) {
  const i = D.frames[f], q = D.q[i];
  cx.clearRect(0, 0, W, H); cx.font = "12px sans-serif";
  for (let j = 0; j < n; j++) {
    cx.strokeStyle = D.colors[j]; cx.globalAlpha = 0.6; cx.lineWidth = 1; cx.beginPath();
    for (let s = 0; s <= i; s++) {
      const p = D.q[s][j];
      s ? cx.lineTo(X(p[0]), Y(p[1])) : cx.moveTo(X(p[0]), Y(p[1]));
    }
    cx.stroke();
  }
  cx.globalAlpha = 1; cx.strokeStyle = "#4d4d4d"; cx.beginPath();
  for (const [a, b] of D.edges) {
    cx.moveTo(X(q[a][0]), Y(q[a][1])); cx.lineTo(X(q[b][0]), Y(q[b][1]));
  }
  cx.stroke();
  for (let j = 0; j < n; j++) {
    cx.globalAlpha = 0.9; cx.fillStyle = D.colors[j]; cx.beginPath();
    cx.arc(X(q[j][0]), Y(q[j][1]), Math.max(D.diameters[j] / 2 * k, 2), 0, 2 * Math.PI);
    cx.fill(); cx.globalAlpha = 1;
    if (D.numbers) { cx.fillStyle = "#000"; cx.fillText(j + 1, X(q[j][0]) + 6, Y(q[j][1]) - 6); }
  }
  bar();
  cx.fillStyle = "#000"; cx.fillText(`${D.title}t = ${D.t[i].toFixed(2)} s`, pad, 16);
  slider.value = f;
}
let f = 0, timer = null;
function stop() { clearInterval(timer); timer = null; button.textContent = "play"; }
function play() {
  if (f >= D.frames.length - 1) f = 0;
  button.textContent = "pause";
  timer = setInterval(() => {
    draw(f);
    if (++f >= D.frames.length) { f--; stop(); }
  }, 1000 / D.fps);
}
slider.max = D.frames.length - 1;
slider.oninput = () => { stop(); f = +slider.value; draw(f); };
button.onclick = () => (timer ? stop() : play());
draw(0); play();
"""


def player_page(
    t: ArrayLike,
    q: ArrayLike,
    frames: ArrayLike,
    *,
    edges: ArrayLike,
    diameters: ArrayLike,
    title: str = "",
    fps: int = 15,
    numbers: bool = True,
) -> str:
    """A self-contained HTML page that animates a run in the plane.

    Parameters
    ----------
    t : array_like, shape (T,)
        The times of the states the page holds (the frames and the trails' states).
    q : array_like, shape (T, n, 2)
        Positions in metres.
    frames : array_like of int, shape (F,)
        Indices into ``t`` of the frames, in order.
    edges : array_like of int, shape (m, 2)
        The graph's edges, 0-based.
    diameters : array_like, shape (n,)
        Robot diameters in metres.
    title, fps, numbers
        The words before the time, frames per second, and whether the robots are numbered.
    """
    q = np.asarray(q, dtype=float)
    data: dict[str, Any] = {
        "t": np.round(np.asarray(t, dtype=float), 6).tolist(),
        "q": np.round(q, 4).tolist(),
        "frames": np.asarray(frames, dtype=int).tolist(),
        "edges": np.asarray(edges, dtype=int).reshape(-1, 2).tolist(),
        "diameters": np.asarray(diameters, dtype=float).tolist(),
        "colors": [to_hex(c) for c in robot_colors(q.shape[1])],
        "title": f"{title}: " if title else "",
        "fps": fps,
        "numbers": numbers,
    }
    states = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return (
        "<!DOCTYPE html>\n<html>\n<head>\n<meta charset='utf-8'>\n"
        f"<title>{html.escape(title)}</title>\n</head>\n<body>\n"
        "<canvas id='view' width='640' height='640'></canvas><br>\n"
        "<button id='play'>play</button> <input id='frame' type='range' min='0' value='0' "
        "style='width:520px'>\n"
        f"<script id='states' type='application/json'>{states}</script>\n"
        f"<script>{_SCRIPT}</script>\n</body>\n</html>\n"
    )
