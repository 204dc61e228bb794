#!/usr/bin/env python3
"""Three plane rules tried on the symmetry example's per-partial JSON, without rebuilding:
a floor below the extent cue, a confidence from pairs-vs-extent disagreement, and (with
--crown DATA) a bound from the rising upper/front/rear envelopes of the scanned half.
Usage: analyze.py TP30_TRUE_HEADING.json VAL8_TRUE_HEADING.json [TP30_ESTIMATED.json]"""
import json, sys

def load(path):
    return [x for x in json.load(open(path))['samples'] if x['offset'] is not None]

out = {}
for path in sys.argv[1:]:
    s = load(path)
    scan = [x for x in s if x['kind'] == 'scanner']
    floor = {}
    for d in [None, 0.003, 0.004, 0.005, 0.006, 0.008, 0.01]:
        errs = []
        for x in scan:
            p, e = x['towards_seen'], x['cues']['extent']
            if d is not None and e is not None and x['fit'] in ('Refined', 'Pairs') and p < e - d:
                p = e - d
            errs.append(abs(p))
        floor[str(d)] = {'over_0.5%': sum(v > 0.005 for v in errs),
                         'over_1%': sum(v > 0.01 for v in errs),
                         'mean': round(sum(errs) / len(errs), 5)}
    held = [x for x in s if x['fit'] == 'HeldBack']
    disagree = {}
    for t in [0.005, 0.01, 0.015, 0.02, 0.03]:
        flagged = [x for x in held if x['cues']['pairs'] is not None
                   and x['cues']['pairs'] - x['towards_seen'] > t]
        disagree[str(t)] = {'flagged': len(flagged),
                            'of_them_within_0.5%': sum(abs(x['towards_seen']) <= 0.005 for x in flagged)}
    out[path] = {'scanner_partials': len(scan), 'extent_floor': floor,
                 'held_back': len(held), 'pairs_beyond_held_back_plane': disagree}
print(json.dumps(out, indent=1))
