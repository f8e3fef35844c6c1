#!/usr/bin/env python3
"""How far two ``vdps replay`` outputs differ, message by message (what ``refcheck`` reports only
as DIFFER): per topic the number of messages, of messages whose bytes differ, the largest
absolute and relative difference of any value or sigma (relative to max(|a|, |b|, 1e-300)),
and the keys whose value changed class (finite / null, e.g. an update accepted in one and gated
in the other: ``accepted``, ``status_code``).

Usage::

    .venv/bin/python tools/replay_diff.py A.mcap B.mcap [--json FILE]

Messages are matched by topic and position within the topic (file order).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict

from mcap.reader import make_reader


def _messages(path: str) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list] = defaultdict(list)
    with open(path, "rb") as fh:
        for _, ch, msg in make_reader(fh).iter_messages(log_time_order=False):
            out[ch.topic].append((msg.publish_time, msg.data))
    return out


def _flat(doc, prefix: str = "") -> dict[str, object]:
    if isinstance(doc, dict):
        out = {}
        for k, v in doc.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: doc}


def compare(a: str, b: str) -> dict:
    ma, mb = _messages(a), _messages(b)
    res = {}
    for topic in sorted(set(ma) | set(mb)):
        la, lb = ma.get(topic, []), mb.get(topic, [])
        r = {"messages": [len(la), len(lb)], "differ": 0, "max_abs": 0.0, "max_rel": 0.0, "time_differs": 0,
             "class_changes": {}}
        for (ta, da), (tb, db) in zip(la, lb):
            if ta != tb:
                r["time_differs"] += 1
            if da == db:
                continue
            r["differ"] += 1
            try:
                fa, fb = _flat(json.loads(da)), _flat(json.loads(db))
            except ValueError:
                continue
            for k in set(fa) | set(fb):
                va, vb = fa.get(k), fb.get(k)
                if isinstance(va, (int, float)) and isinstance(vb, (int, float)) and not isinstance(va, bool):
                    d = abs(va - vb)
                    if math.isfinite(d):
                        r["max_abs"] = max(r["max_abs"], d)
                        r["max_rel"] = max(r["max_rel"], d / max(abs(va), abs(vb), 1e-300))
                    if (k.endswith("accepted") or k.endswith("status_code")) and va != vb:
                        r["class_changes"][k] = r["class_changes"].get(k, 0) + 1
                elif va != vb:
                    r["class_changes"][k] = r["class_changes"].get(k, 0) + 1
        res[topic] = r
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    try:
        res = compare(args.a, args.b)
    except Exception as e:  # an unreadable or broken recording: one line, no traceback
        print(f"replay_diff: error: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    for topic, r in res.items():
        if r["differ"] or r["messages"][0] != r["messages"][1] or r["time_differs"]:
            print(f"{topic}: {r['messages'][0]} / {r['messages'][1]} messages, {r['differ']} differ, "
                  f"max abs {r['max_abs']:.3g}, max rel {r['max_rel']:.3g}, times differ {r['time_differs']}"
                  + (f", changed: {r['class_changes']}" if r["class_changes"] else ""))
    same = [t for t, r in res.items() if not r["differ"] and r["messages"][0] == r["messages"][1]]
    print(f"identical topics: {len(same)} of {len(res)}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(res, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
