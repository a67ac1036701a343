"""The header every report starts with (command, machine, frames, seeds, weights) and writing reports.

A report names the command that reproduces it, ``python -m bench.<module> <arguments>``
(:func:`command_line`), then the machine, the frames and the seeds (:func:`section`).

May import :mod:`sparsedepth` and :mod:`.machine`.
"""

from __future__ import annotations

from pathlib import Path

import sparsedepth as sd

from .machine import machine_markdown

__all__ = ["REPO", "DOCS", "command_line", "weights_markdown", "frames_markdown", "step_note", "section",
           "tuned_report_header", "write_text"]

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"


def command_line(module: str, argv=()) -> str:
    """``python -m bench.<module> <argv>``: the command that reproduces a report."""
    return " ".join(["python", "-m", f"bench.{module}", *map(str, argv)])


def weights_markdown(w) -> str:
    """``alpha = 1, beta = ...``: every weight of a :class:`sparsedepth.Weights` or a
    :class:`sparsedepth.DensitySchedule`.

    ``edge_penalty`` and ``edge_scale`` are listed only for a robust edge
    penalty (with the default ``"l1"`` the scale is unused).  A schedule is
    its base's other fields, then each anchor's scheduled fields
    (``at 1 % observed: delta = ...``).
    """
    if isinstance(w, sd.DensitySchedule):
        scheduled = set(w.anchors[0][1])
        base = {k: v for k, v in w.base.as_dict(used_only=True).items() if k not in scheduled}
        anchors = "; ".join(f"at {100 * f:g} % observed: " + _items_markdown(values) for f, values in w.anchors)
        return f"{_items_markdown(base)}; {anchors}"
    return _items_markdown(w.as_dict(used_only=True))


def _items_markdown(items) -> str:
    return ", ".join(f"{k} = {v}" if isinstance(v, str) else f"{k} = {v:g}" for k, v in items.items())


def tuned_report_header(title, command, args, seconds, tune_frames, report_frames) -> list[str]:
    """The first lines of a report that tunes on TUNE_FRAMES and reports on REPORT_FRAMES: title, command, machine,
    frames."""
    return [
        f"# {title}",
        "",
        f"Made by `{command}` (frames subsampled by {args.step}, sampling seeds {args.seeds}, {seconds:.0f} s).",
        "",
        machine_markdown(),
        "",
        "Tuning frames: " + ", ".join(f"`{f.name}`" for f in tune_frames) + ".",
        "Report frames (never used for a choice): " + ", ".join(f"`{f.name}`" for f in report_frames) + ".",
    ]


def frames_markdown(frames_) -> str:
    """The frames' names and sizes, for a report header."""
    return ", ".join(f"`{f.name}` {f.shape[1]}x{f.shape[0]}" for f in frames_)


def step_note(args) -> str:
    """One sentence on how the frames were reduced."""
    if args.quick:
        return "Quick mode: tiny frames (smoke test only; not a result)."
    if args.step == 1:
        return "Frames at full resolution."
    return (f"Frames subsampled by keeping one pixel in {args.step}x{args.step} (`[::{args.step}, ::{args.step}]` of "
            "the ground truth and the image alike, no interpolation) to keep the run short.")


def section(title, *, command, frames_, seeds, body, notes="", elapsed=None) -> str:
    """A results section: title, the command, machine, frames, seeds, then the body."""
    lines = [f"## {title}", "", f"Command: `{command}`", "",
             f"Machine: {machine_markdown()}.", "",
             f"Frames ({len(frames_)}): {frames_markdown(frames_)}.", "",
             f"Seeds: {', '.join(map(str, seeds))}. Default weights at run time: {weights_markdown(sd.DEFAULT_SCHEDULE)}."]
    if elapsed is not None:
        lines += ["", f"Wall time of this section: {elapsed:.0f} s."]
    if notes:
        lines += ["", notes.strip()]
    lines += ["", body.strip(), ""]
    return "\n".join(lines)


def write_text(path, text: str) -> None:
    """Write ``text`` to ``path``, creating its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def publish(lines, out) -> int:
    """Print the report made of ``lines`` and write it to ``out`` when given (a script's last step); returns 0."""
    text = "\n".join(lines)
    print(text)
    if out is not None:
        write_text(out, text)
    return 0
