"""Files a person opens: the run in 3D (``replay.html``) and the diagram's picture.

- :func:`write_replay` saves the Meshcat recording (:mod:`nsdrake.station.visualization`)
  as ``replay.html``: ``Meshcat.StaticHtml()``, the three.js viewer with its scripts
  inlined and the recording as an animation with a time slider; it opens from the file
  system with no network.
- :func:`write_diagram_picture` writes ``diagram.dot`` (Drake's ``GetGraphvizString``)
  and, when Graphviz's ``dot`` is on the PATH, ``diagram.svg``.
"""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram

# Appended to Meshcat's static page: once the recording's animation is loaded, show it
# at t = 0, paused, with a play button and the time in a bar at the top of the window and
# Meshcat's own controls (Animations: play, pause, the time slider) open. Meshcat alone
# opens the page on the animation's last frame with its controls folded away.
START_AT_ZERO = """
<div id="nsdrake-replay-bar" style="position:fixed;top:0;left:0;z-index:10;margin:8px;padding:6px 10px;
 background:rgba(255,255,255,0.92);border-radius:6px;font:14px system-ui,sans-serif;color:#222">
 <button id="nsdrake-play" type="button" style="font-size:15px;padding:2px 12px">&#9654; play</button>
 <span id="nsdrake-time" style="margin-left:8px;font-variant-numeric:tabular-nums">t = 0.000 s</span>
</div>
<script>
(function () {
  const button = document.getElementById("nsdrake-play");
  const label = document.getElementById("nsdrake-time");
  const animator = () => viewer.animator;
  const now = () => animator().actions.reduce((t, a) => Math.max(t, a.time), 0);
  let shown = false;
  function showStart() {
    if (shown || !(animator().duration > 0)) return;
    shown = true;
    animator().pause();
    animator().reset();  // every action back to t = 0, the scene drawn there
    viewer.gui.open();
    animator().folder.open();
  }
  button.addEventListener("click", () => {
    if (animator().playing) { animator().pause(); } else { animator().play(); }
  });
  (function tick() {
    showStart();
    if (shown) {
      button.innerHTML = animator().playing ? "&#10074;&#10074; pause" : "&#9654; play";
      label.textContent = "t = " + now().toFixed(3) + " s of " + animator().duration.toFixed(3) + " s";
    }
    requestAnimationFrame(tick);
  })();
})();
</script>
"""


def write_replay(meshcat: Meshcat, path: Path) -> Path:
    """Saves the scene and its published recording as one self-contained HTML file, which
    opens at t = 0 with its play button in view (START_AT_ZERO)."""
    path = Path(path)
    page = meshcat.StaticHtml()
    end = page.rfind("</body>")
    if end < 0:
        raise ValueError("Meshcat's static page has no </body>: cannot add the replay's play bar")
    path.write_text(page[:end] + START_AT_ZERO + page[end:], encoding="utf-8")
    return path


RENDER_HINT = "render it with: dot -Tsvg {dot} -o {svg}  (Graphviz; Debian: apt-get install graphviz)"


@dataclass
class DiagramPicture:
    dot: Path
    svg: Path | None  # None when Graphviz's dot was not found
    note: str  # one line for the user when the SVG is missing, else ""


def write_diagram_picture(diagram: Diagram, out: Path, *, stem: str = "diagram") -> DiagramPicture:
    """Writes ``stem.dot`` and, if Graphviz's ``dot`` is on the PATH, ``stem.svg``.

    Every system appears under its name (``set_name``), two levels deep, so the
    controller's box shows the paper's structure inside it (robot terms,
    impedance, criteria, priority selector, null-space controller). The plant is
    split into its inputs and its outputs (Drake's ``"split": "I/O"`` option), so
    the signals flow left to right from the plant's outputs, through the
    controllers, back to its actuation.
    """
    out = Path(out)
    dot_path = out / f"{stem}.dot"
    text = diagram.GetGraphvizString(max_depth=2, options={"plant/split": "I/O"})
    dot_path.write_text(text, encoding="utf-8")
    svg_path = out / f"{stem}.svg"
    hint = RENDER_HINT.format(dot=dot_path, svg=svg_path)
    dot = shutil.which("dot")
    if dot is None:
        return DiagramPicture(
            dot_path, None, f"Graphviz's dot was not found: wrote {dot_path.name} only; {hint}"
        )
    result = subprocess.run(
        [dot, "-Tsvg", str(dot_path), "-o", str(svg_path)], capture_output=True, text=True, timeout=120
    )
    if result.returncode != 0 or not svg_path.is_file():
        problem = " ".join(result.stderr.split())[:200] or f"exit status {result.returncode}"
        svg_path.unlink(missing_ok=True)
        return DiagramPicture(dot_path, None, f"dot failed ({problem}): wrote {dot_path.name} only")
    return DiagramPicture(dot_path, svg_path, "")
