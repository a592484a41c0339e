"""The interactive report: one self-contained HTML page per archive (docs/figures.md).

``page(tree)`` takes an archive as the nested dict ``designopt.io.archive.read`` returns and
gives one HTML document that works offline, with no server: plotly.js is embedded once
(about 4.8 MB), every plot's data follows as JSON (numeric arrays as base64 typed arrays,
exact float64), and one script draws them. ``write(tree, path)`` writes the page through
the one writer (``designopt.io.writer``).

What a page shows, by the root attr ``kind``:

- ``run``: the best-so-far f of every run and the best run, the best run's indices over the
  iterations (± 2 SE bands where ``<index>_se`` exists; success rates clipped to [0, 1]
  with a Wilson band), the final design and its indices ± SE, the config; a replay
  (``teleop/``) its paths and tracking error;
- a ``front`` group (any kind): the Pareto front in 2-D with ± 2 SE bars, in 3-D for three
  objectives, a scatter matrix for more, hover showing each design's variables and
  indices ± SE, pairs whose order is within 2 SE (``front/ambiguous``) marked, and the
  hypervolume history when archived;
- ``scan``: curves (one varied variable) or heat maps (a two-variable grid) of f and every
  index, infeasible designs marked; otherwise f ± 2 SE per design;
- ``sweep``: the final f ± 2 SE per member and the members' convergence;
- ``bench``: per case, box plots of the final values per optimizer, the median convergence
  curves (band: interquartile range), the hypervolume when the entries carry it, and the
  statistics table;
- ``ik``: the success rate (Wilson interval) and histograms of the errors;
- ``cloud`` (an argument): a 3-D point cloud of the workspace coloured by a value;
- ``robot`` (an argument): the robot in 3-D (``robot.View``: in its task, a slider
  through representative poses; ``robot.FrontView``: a front beside the robot of the
  design hovered or clicked).

Size: each plot keeps at most :data:`MAX_RUN_LINES` runs, :data:`MAX_LINE_POINTS` points
per curve, :data:`MAX_MARKERS` designs per scatter, :data:`MAX_CLOUD` cloud points and
:data:`MAX_CELLS` cells per heat map (evenly thinned, the last point kept; the plot's title
says so); then the whole page is thinned further until its plots hold at most
:data:`MAX_VALUES` numbers, so a page stays under about 8 MB (plotly.js included).

The package: ``model`` (the page model, size caps, small helpers), ``plots`` (shared plot
helpers), ``run``, ``front``, ``scan`` (with sweeps), ``bench`` (with ik and the cloud),
``robot`` (the robot's 3-D views), ``budget`` (the size budget) and ``page`` (sections by
kind, the document, the writer).
"""

from designopt.figures.html.budget import budget
from designopt.figures.html.front import front_objectives
from designopt.figures.html.model import (
    CONFIG,
    INFEASIBLE_MARKER,
    MAX_CELLS,
    MAX_CLOUD,
    MAX_LINE_POINTS,
    MAX_MARKERS,
    MAX_RUN_LINES,
    MAX_TEXT,
    MAX_VALUES,
    PALETTE,
    PageSection,
    Plot,
    Z,
    esc,
)
from designopt.figures.html.page import CSS, JS_DRAW, document, page, sections, write
from designopt.figures.html.plots import merged
from designopt.figures.html.robot import FrontView, Pose, View, robot_section

__all__ = [
    "CONFIG",
    "CSS",
    "FrontView",
    "INFEASIBLE_MARKER",
    "JS_DRAW",
    "MAX_CELLS",
    "MAX_CLOUD",
    "MAX_LINE_POINTS",
    "MAX_MARKERS",
    "MAX_RUN_LINES",
    "MAX_TEXT",
    "MAX_VALUES",
    "PALETTE",
    "Z",
    "Plot",
    "PageSection",
    "Pose",
    "View",
    "budget",
    "document",
    "esc",
    "front_objectives",
    "merged",
    "page",
    "robot_section",
    "sections",
    "write",
]
