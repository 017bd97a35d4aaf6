"""A long run's routine may log without end: the runner keeps the latest lines only (every
line still goes to the log's sink, `mexone run`'s output)."""

from __future__ import annotations

from mexone.lab import Lab
from mexone.routines import runner as runner_module
from mexone.routines.runner import RoutineRunner


def test_the_runner_keeps_the_latest_log_lines(tmp_path, monkeypatch):
    monkeypatch.setattr(runner_module, "LOG_KEEP", 100)
    path = tmp_path / "chatty.py"
    path.write_text("from mexone import rospy\nrospy.init_node('chatty')\n"
                    "for i in range(1000):\n    rospy.loginfo('line %d', i)\n")
    printed = []
    runner = RoutineRunner(Lab.create(), path, log=lambda level, text: printed.append(text))
    runner.run(0.01)
    assert printed == [f"line {i}" for i in range(1000)]
    texts = [text for _, _, text in runner.log_lines]
    assert 100 <= len(texts) < 200 and texts[-1] == "line 999"
    assert texts == printed[-len(texts):]
