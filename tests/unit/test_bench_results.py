"""make bench rewrites bench/RESULTS.md: the sections it writes replace theirs, the others
(the real sensor's, written where that data is at hand) are kept as they were, once."""

from __future__ import annotations

from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from run_bench import _kept_sections  # noqa: E402


def test_written_sections_replace_theirs_and_the_rest_is_kept_once(tmp_path):
    old = tmp_path / "RESULTS.md"
    old.write_text("# results\n\n## Ratios\n\nold ratio\n\n## Stripe extraction\n\nold stripes\n\n"
                   "## Real sensor: the Blaser UR5e sessions\n\nblaser figures\n")
    # a benchmark script's section arrives as one multi-line entry
    written = ["# results", "", "## Ratios", "", "new ratio", "",
               "## Stripe extraction\n\nnew stripes"]
    kept = _kept_sections(old, written)
    assert kept[0] == "## Real sensor: the Blaser UR5e sessions"
    assert "blaser figures" in kept
    assert not any("old" in ln for ln in kept)
