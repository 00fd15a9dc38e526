"""The runner's provenance record (``procedures.procedure.Span``): spans join only when back to
back in one file, and a span whose file moved is found beside the file that recorded it."""

from __future__ import annotations

from pathlib import Path

from procedures.procedure import Span, merge_spans


def test_merge_spans_joins_adjacent_pieces_of_one_file_only():
    a, b = Path("a.h5"), Path("b.h5")
    spans = [
        Span(a, 0, 10, 50.0),
        Span(a, 10, 20, 50.0),
        Span(b, 5, 15, 50.0),
        Span(b, 20, 30, 50.0),
    ]
    assert merge_spans(spans) == [Span(a, 0, 20, 50.0), Span(b, 5, 15, 50.0), Span(b, 20, 30, 50.0)]
    # another rate is another stretch, even back to back
    assert merge_spans([Span(a, 0, 10, 50.0), Span(a, 10, 20, 100.0)]) == [
        Span(a, 0, 10, 50.0),
        Span(a, 10, 20, 100.0),
    ]
    assert merge_spans([]) == []


def test_span_round_trips_and_follows_a_moved_run_directory(tmp_path):
    s = Span(Path("/gone/run/drift.h5"), 100, 400, 50.0)
    assert s.samples == 300
    assert (
        Span.from_json(s.to_json(), tmp_path / "drift-2.h5") == s
    )  # nothing beside: kept as recorded
    (tmp_path / "drift.h5").write_bytes(b"")
    moved = Span.from_json(s.to_json(), tmp_path / "drift-2.h5")
    assert moved == Span(tmp_path / "drift.h5", 100, 400, 50.0)
