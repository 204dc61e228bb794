#!/usr/bin/env python3
"""The crown bound: on a drive-by, the upper envelope (and the front and rear ones) of a
symmetric vehicle falls away from its plane, so while it still rises from the scanned flank
towards the far side the plane lies beyond the middle of any two points of that rising run.
Applied to the symmetry example's planes (true heading) as an upper bound towards the scanner.
Usage: crown.py EXAMPLE.json DATA/clouds/test/"""
import json, sys
import numpy as np

def read_ply(path):
    with open(path, 'rb') as f:
        n, props = None, []
        while True:
            line = f.readline().decode().strip()
            if line.startswith('element vertex'):
                n = int(line.split()[-1])
            elif line.startswith('property'):
                props.append(line.split()[1:])
            elif line == 'end_header':
                break
        kinds = {'float': '<f4', 'uchar': 'u1', 'double': '<f8'}
        a = np.frombuffer(f.read(), dtype=np.dtype([(n_, kinds[t]) for t, n_ in props]), count=n)
    return np.stack([a['x'], a['y'], a['z']], 1).astype(float)

def to_object(p, yaw_deg):
    y = np.radians(yaw_deg)
    along = np.array([np.sin(y), 0, np.cos(y)])
    across = np.array([along[2], 0, -along[0]])
    out = np.outer(p[:, 0], across) + np.outer(p[:, 2], along)
    out[:, 1] += p[:, 1]
    return out

def envelope_bound(x, h, binw=0.005, margin=0.004, minpts=3):
    hi = x.max()
    nb = int(np.ceil((hi - x.min()) / binw)) + 1
    idx = ((hi - x) / binw).astype(int)
    top = np.full(nb, -np.inf)
    cnt = np.zeros(nb, int)
    np.maximum.at(top, idx, h)
    np.add.at(cnt, idx, 1)
    centres = hi - (np.arange(nb) + 0.5) * binw
    run, best, gap = [], -np.inf, 0
    for b in range(nb):
        if cnt[b] < minpts:
            gap += 1
            if gap > 2 and run:
                break
            continue
        gap = 0
        if top[b] < best - margin:
            break
        best = max(best, top[b])
        run.append(b)
    bound = np.inf
    for i, b1 in enumerate(run):
        for b2 in run[:i]:
            if top[b1] > top[b2] + margin:
                bound = min(bound, (centres[b1] + centres[b2]) / 2)
    return bound

rows = []
for s in json.load(open(sys.argv[1]))['samples']:
    if s['kind'] != 'scanner' or s['offset'] is None:
        continue
    cat, name, part = s['name'].split('/')
    k = int(part.split('_')[1])
    d = f"{sys.argv[2]}/{cat}/{name}/"
    spec = [x for x in json.load(open(d + 'done.json'))['samples'] if x['k'] == k][0]['spec']
    gt = read_ply(d + 'gt.ply')
    p = to_object(read_ply(d + part + '.ply'), spec['yaw_deg']) / (gt[:, 2].max() - gt[:, 2].min())
    side = np.sign(p[:, 0].mean())
    x = p[:, 0] * side
    bound = min(envelope_bound(x, h) for h in (p[:, 1], p[:, 2], -p[:, 2]))
    est = s['towards_seen']
    rows.append({'name': s['name'], 'plane': est, 'bound': None if np.isinf(bound) else float(bound),
                 'bounded': float(min(est, bound))})
before = [abs(r['plane']) for r in rows]
after = [abs(r['bounded']) for r in rows]
print(json.dumps({'partials': len(rows),
                  'over_0.5%': [int(sum(v > 0.005 for v in before)), int(sum(v > 0.005 for v in after))],
                  'over_1.5%': [int(sum(v > 0.015 for v in before)), int(sum(v > 0.015 for v in after))],
                  'moved': [r for r in rows if r['bounded'] != r['plane']]}, indent=1))
