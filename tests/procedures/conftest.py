"""Helpers the procedure tests share."""

from __future__ import annotations


def assert_spans_are_the_record_steps(first, second, names, n_taken, step_s):
    """The resumed analysis reads what an uninterrupted run would: every record step's samples
    once, each where its step ran (the first ones in the aborted file, from the sample its step
    began at), and no setup samples; the same count as an uninterrupted run."""
    from daq.reader import RunFile

    assert list(second.spans) == names
    rate = second.spans[names[0]].rate_hz
    for i, name in enumerate(names):
        span = second.spans[name]
        here = first if i < n_taken else second
        assert span.file == here.file.resolve() and span.samples == round(step_s * rate)
        with RunFile(here.file) as rf:
            began = next(e.time_s for e in rf.events if e.kind == "step" and e.text.endswith(name))
        assert span.start == round(began * rate)
    assert sum(s.samples for s in second.spans.values()) == round(len(names) * step_s * rate)
