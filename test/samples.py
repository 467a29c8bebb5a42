"""Small documents shared by the tests of several packages."""

from __future__ import annotations

# A valid lvws-instance/1 document: three tasks, a subteam needed for t0, a robot with an extra key.
BASE = {
    "format": "lvws-instance/1",
    "name": "tiny",
    "capabilities": ["manipulation", "mobility"],
    "robots": [
        {"id": "r0", "capabilities": [1, 0], "payload": 12.0},
        {"id": "r1", "capabilities": [0, 1], "payload": 3.0, "pose": [1, 2]},
    ],
    "tasks": [
        {"id": "t0", "capabilities": [1, 1], "payload": 14.0, "duration": 4.0, "after": []},
        {"id": "t1", "capabilities": [0, 1], "payload": 2.0, "duration": 7.0, "after": ["t0"]},
        {"id": "t2", "capabilities": [1, 0], "payload": 0.0, "duration": 1.5, "after": ["t0", "t1"]},
    ],
}
