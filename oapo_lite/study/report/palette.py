"""One colour per curve, in every figure and inline plot: the palette's one table.

A curve keeps its colour wherever it is drawn, and two curves never share one: algorithms,
OAPPO's readings and settings, the reuse schemes of Fig. 5b and the values of Fig. 3c's sigma
and Fig. 3d's lambda each have their own. The mazes' agents are named after their colours (red,
black, blue), so no curve is red, black or blue (``forbidden`` says which hues those are). The
reusing curves trained with Algorithm 1's sampled source are drawn dashed (``dashes``), so that
a curve and its sampled twin never hide each other. A label the table lacks is an error, not a
colour picked by matplotlib: a new curve gets a row here.
"""
from __future__ import annotations

# sigma and lambda at the paper's values (0.1, 0.7) are OAPPO itself, and drawn as it is
OAPPO = "#2ca02c"
PALETTE = {
    # the algorithms
    "oappo": OAPPO, "oatrpo": "#9467bd", "mappo": "#ff7f0e", "happo": "#8c564b", "hatrpo": "#e377c2",
    "ippo": "#7f7f7f", "seac": "#bcbd22", "seps": "#17becf",
    # OAPPO's readings of the networks and its gate statistics
    "oappo one seat": "#98df8a", "oappo type": "#01665e",
    "oappo agent max": "#005a32", "oappo agent mean": "#41ab5d", "oappo agent q90": "#a1d99b",
    "oappo type max": "#3f007d", "oappo type mean": "#807dba", "oappo type q90": "#c6c3e0",
    # the selection ablation: gated reuse (Eq. 8's weights, and a sampled source), always-on reuse, and per type
    # within its type only
    "oappo gated": "#006d2c", "oappo always": "#d4a017", "oappo type gated": "#35978f", "oappo type own type": "#80cdc1",
    "oappo gated sampled": "#7b6888", "oappo always sampled": "#e7cb94",
    # the dose-responses on 2s3z and Ant 4x2: the gate at sigma from tight (darker) to loose
    # (lighter), between no reuse (HAPPO) and always-on; a median sigma of 0.046 is the gated
    # curve's colour (``ALIASES``)
    "oappo sigma=0.031": "#0b3b1f", "oappo sigma=0.035": "#00441b", "oappo sigma=0.077": "#238b45",
    "oappo sigma=0.11": "#74c476", "oappo sigma=0.34": "#78c679", "oappo sigma=0.81": "#addd8e",
    # OAPPO's variants
    "oappo adaptive": "#145214", "oappo adaptive lambda=0.4": "#637939", "oappo warm-up 10": "#8ca252",
    "oappo entropy x W[i,i]": "#cedb9c",
    # Fig. 3c's sigma and Fig. 3d's lambda (the paper's values are OAPPO's)
    "sigma = 0.01": "#fdae6b", "sigma = 0.1": OAPPO, "sigma = 1": "#e6550d", "sigma = 10": "#7a0177",
    "lambda = 0.2": "#756bb1", "lambda = 0.4": "#9e9ac8", "lambda = 0.7": OAPPO, "lambda = 1": "#c49c94",
    # Fig. 5b's reuse schemes
    "NR": "#636363", "UR": "#ce6dbd", "RR": "#6a3d9a", "AR": "#fd8d3c",
    # HAPPO's settings on HalfCheetah, and the one-agent control
    "happo clip 0.05": "#bd9e39", "happo 15 epochs": "#8c6d31", "happo 128x3": "#e7ba52", "happo feature norm": "#7b4173",
    "happo 20 x 200": "#a55194", "happo HARL": "#b5cf6b", "happo normalized": "#de9ed6", "ppo one agent": "#969696",
    "sb3 ppo (one agent)": "#525252",
}
# what is not a curve: Fig. 1's reused and omitted peers (and the mazes' agents, whose colours
# are ``envs.render.AGENT_COLOURS``)
REUSED, OMITTED = "#e6a100", "#9a9a9a"
# a verdict's status, in the figure that counts them: the interval's four readings from the
# paper's side (dark green) to the other (purple), then the statuses that read no interval in greys
STATUS = {"reproduced": "#1b7837", "within noise": "#a6dba0", "not reproduced": "#c2a5cf", "contradicted": "#762a83",
          "not a test of reuse": "#636363", "a test of sharing": "#969696", "not a test of selection": "#bdbdbd",
          "not testable at this budget": "#d9d9d9", "not run": "#f0f0f0"}
# the greys apart by hatching too: five light shades are hard to tell apart in print
STATUS_HATCH = {"not a test of reuse": "//", "a test of sharing": "\\\\", "not a test of selection": "xx",
                "not testable at this budget": "..", "not run": ""}
# other names of a curve in the table (the same runs drawn in another figure)
ALIASES = {"oappo lambda=0.4": "lambda = 0.4", "oappo lambda=1": "lambda = 1", "oappo lambda=0.2": "lambda = 0.2",
           "happo two legs": "happo", "oappo sigma=0.046": "oappo gated"}


def name(label) -> str:
    """The table's name of a curve label: a sigma or lambda sweep's value as "sigma = 0.1" (its
    float label is named by the caller, who knows which sweep), an alias as its curve."""
    text = str(label).strip()
    return ALIASES.get(text, text)


def color(label) -> str:
    """The colour of curve ``label`` (any case)."""
    key = name(label)
    for candidate in (key, key.lower()):
        if candidate in PALETTE:
            return PALETTE[candidate]
    raise ValueError(f"no colour for the curve {label!r}; add it to oapo_lite.study.report.palette.PALETTE")


def forbidden(colour: str) -> str | None:
    """Which of the agents' colours ``colour`` reads as (red, blue or black), or None: a bright red
    (a hue within 15 degrees of red, saturation above 0.5 and value above 0.6: browns are not red),
    a blue (a hue between 195 and 245 degrees, saturation above 0.35), or black (value below 0.2)."""
    import colorsys

    r, g, b = (int(colour[k:k + 2], 16) / 255 for k in (1, 3, 5))
    hue, saturation, value = colorsys.rgb_to_hsv(r, g, b)
    degrees = 360 * hue
    if value < 0.2:
        return "black"
    if saturation > 0.5 and value > 0.6 and (degrees < 15 or degrees > 345):
        return "red"
    if saturation > 0.35 and 195 <= degrees <= 245:
        return "blue"
    return None


def dashes(label) -> str:
    """The line style of curve ``label``: dashed for a curve trained with a sampled source."""
    return "--" if str(label).endswith("sampled") else "-"
