"""The terminal summary of ``hpe evaluate``: the same content as the HTML page, as aligned text lines."""

from __future__ import annotations

ANGLES = ("pitch", "yaw", "roll")
#: groups printed per --by / --yaw-bins table (the JSON and the HTML page hold more)
MAX_GROUPS = 40
_SKIP = {"n", "dropped", "pitch", "yaw", "roll", "mean", "system", "source", "notes", "units", "re_expressed"}


def _v(x, w=8, d=3):
    if isinstance(x, bool) or x is None or not isinstance(x, (int, float)):
        return f"{'-':>{w}}"
    return f"{x:{w}.{d}f}"


#: below this geodesic error (degrees) every prediction is its GT rotation, up to rounding
SAME_ROTATION_DEG = 1e-3


def same_rotation_notes(result: dict) -> list:
    """Why a protocol scores an error although every prediction is its GT rotation (the README tour's case).

    Euler-angle protocols compare the three numbers as written. A rotation has two Euler solutions, and a GT row
    stated with the other one or past its system's range (``hpe audit``: non_canonical, out_of_range) differs from
    the prediction's numbers by up to 180 degrees per angle although the rotations are equal; at the gimbal lock
    only the sum or difference of the first and last angles is defined, so the split can differ too.
    """
    g = result.get("metrics", {}).get("geodesic", {})
    top = g.get("max")
    if top is None or not top < SAME_ROTATION_DEG:
        return []
    scored = [
        f"{name} {p['mean']:.3f}"
        for name, p in result.get("protocols", {}).items()
        if p.get("units", "deg") == "deg" and isinstance(p.get("mean"), float) and p["mean"] > 0.01
    ]
    if not scored:
        return []
    return [
        f"every prediction is its GT rotation (geodesic max < {SAME_ROTATION_DEG:g} deg), yet "
        + ", ".join(scored)
        + ": Euler-angle protocols compare the angles as written, and a GT row written with the other Euler "
        "solution, past its system's range or at the gimbal lock (hpe audit counts them: non_canonical, "
        "out_of_range, gimbal_lock) has other numbers than the prediction for the same rotation"
    ]


def _counts(result, verbose: bool = False) -> str:
    n = result["n"]
    line = (
        f"pairs {n['pairs']} of {n['gt']} GT rows ({n['pred']} predictions): missing {n['missing']}, "
        f"invalid {n['invalid']}, unmatched predictions {n.get('unmatched_pred', 0)}"
    )
    if n.get("unreadable"):
        line += f", unreadable {n['unreadable']}"
    if n.get("orthonormalized") is not None:
        line += f", orthonormalized {n['orthonormalized']}"
    inp = result.get("inputs", {})
    origin = result.get("system_origin") or {k: v for k, v in result["systems"].items()}
    paired = f" ({inp['paired']})" if verbose and inp.get("paired") else ""  # how: internals, shown with -v
    return line + f"; systems pred {origin['pred']}, gt {origin['gt']}; key {inp.get('key', '?')}{paired}"


def _metrics(m) -> list:
    g = m["geodesic"]
    out = [
        f"{'metric':<17}{'unit':<9}{'pitch':>8}{'yaw':>8}{'roll':>8}{'mean':>8}   detail",
        f"{'geodesic':<17}{'deg':<9}{'':>24}{_v(g['mean'])}   median {_v(g['median'], 0)}, p90 {_v(g['p90'], 0)}, "
        f"p95 {_v(g['p95'], 0)}, max {_v(g['max'], 0)}; within 5/10/15/30: "
        + "/".join(_v(g[f"within_{t}"], 0) for t in (5, 10, 15, 30)),
    ]
    mv = m["maev"]
    out.append(
        f"{'maev':<17}{'deg':<9}{'':>24}{_v(mv['mean'])}   left {_v(mv['left'], 0)}, down "
        f"{_v(mv['down'], 0)}, front {_v(mv['front'], 0)}"
    )
    out.append(f"{'frobenius':<17}{'unitless':<9}{'':>24}{_v(m['frobenius']['mean'], 8, 4)}   ||I - P G^T||_F")
    for k in ("mae_wrapped", "mae_best_of_two"):
        e = m[k]
        out.append(f"{k:<17}{'deg':<9}{_v(e['pitch'])}{_v(e['yaw'])}{_v(e['roll'])}{_v(e['mean'])}")
    return out


def _extras(p) -> str:
    out = []
    for k, v in p.items():
        if k in _SKIP:
            continue
        if isinstance(v, dict):
            s = f"{k} " + _v(v.get("mean"), 0).strip()
            out.append(s + (f" (n {v['n']})" if "n" in v else ""))
        else:
            out.append(f"{k} {v}" if isinstance(v, int) else f"{k} {_v(v, 0).strip()}")
    rx = p.get("re_expressed")
    if rx:
        out.append("re-expressed " + ", ".join(f"{s} {v}" for s, v in rx.items()))
    return ", ".join(out)


def _protocols(protocols) -> list:
    out = [f"{'protocol':<17}{'unit':<9}{'pitch':>8}{'yaw':>8}{'roll':>8}{'mean':>8}{'n':>9}{'dropped':>9}   extras"]
    for name, p in protocols.items():
        unit = p.get("units", "deg")
        d = 4 if unit == "unitless" else 3
        out.append(
            f"{name:<17}{unit:<9}{_v(p.get('pitch'))}{_v(p.get('yaw'))}{_v(p.get('roll'))}"
            f"{_v(p.get('mean'), 8, d)}{p['n']:>9}{p['dropped']:>9}   {_extras(p)}"
        )
        out.append(f"{'':<17}source {p.get('source', '')}")
    return out


#: the widest line of a --by / --yaw-bins table; wider tables continue in blocks of protocol columns below
WIDTH = 100


def _groups(title, groups, protocols) -> list:
    """One row per group: n and the core metrics, then one mean per protocol. Protocol columns that do not fit in
    :data:`WIDTH` characters continue in further blocks (each with the group column), so nothing scrolls."""
    names = list(protocols)
    w = max([len(title)] + [len(str(k)) for k, _ in groups] + [6]) + 2
    shown, more = groups[:MAX_GROUPS], len(groups) - MAX_GROUPS
    fixed = f"{'n':>9}{'geo mean':>10}{'median':>9}{'p90':>9}{'mae_wr':>9}"
    per_block = max(1, (WIDTH - w - len(fixed)) // 11)
    rest = max(1, (WIDTH - w) // 11)
    blocks, i = [names[:per_block]], per_block
    while i < len(names):
        blocks.append(names[i : i + rest])
        i += rest
    out = []
    for b, block in enumerate(blocks):
        if b:
            out.append("")
        head = f"{title:<{w}}" + (fixed if b == 0 else "") + "".join(f"{n[:10]:>11}" for n in block)
        out.append(head)
        for k, s in shown:
            g = s["metrics"]["geodesic"]
            line = f"{k!s:<{w}}"
            if b == 0:
                line += (
                    f"{s['n']:>9}{_v(g['mean'], 10)}{_v(g['median'], 9)}{_v(g['p90'], 9)}"
                    f"{_v(s['metrics']['mae_wrapped']['mean'], 9)}"
                )
            out.append(line + "".join(_v(s["protocols"][n].get("mean"), 11) for n in block))
    if more > 0:
        out.append(f"... {more} more groups (all of them in --json and --report)")
    return out


def summary_lines(result: dict, verbose: bool = False) -> list:
    """The readable summary: counts, metrics, protocols with sources, --by and --yaw-bins tables, notes
    (``verbose``: also how the tables were paired, e.g. the join's partitions)."""
    lines = [_counts(result, verbose)]
    al = result.get("align", {})
    if al.get("method") == "mean":
        a = al["offset_angles"]
        lines.append(
            f"aligned (hpe chordal mean, not opal23's): removed a constant offset of {al['offset_deg']:.3f}"
            f" deg (pitch {a['pitch']:.3f}, yaw {a['yaw']:.3f}, roll {a['roll']:.3f} in {al['gt_system']});"
            f" geodesic mean before {al['before']['metrics']['geodesic']['mean'] or 0:.3f}"
        )
    lines += _metrics(result["metrics"])
    if result.get("protocols"):
        lines += _protocols(result["protocols"])
    if result.get("by"):
        lines.append(f"by {result['by']['column']} (degrees; dad3dheads unitless):")
        lines += _groups(result["by"]["column"], list(result["by"]["groups"].items()), result["protocols"])
    if result.get("yaw_bins"):
        lines.append("by GT yaw (degrees; dad3dheads unitless):")
        lines += _groups("GT yaw", [(f"[{b['lo']:g},{b['hi']:g})", b) for b in result["yaw_bins"]], result["protocols"])
    for note in same_rotation_notes(result) + list(result.get("notes", [])):
        lines.append(f"note: {note}")
    if result.get("rejects"):
        lines.append("rejects: " + ", ".join(f"{k} {v}" for k, v in result["rejects"].items()))
    return lines
