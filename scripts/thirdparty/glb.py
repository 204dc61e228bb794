#!/usr/bin/env python3
"""Build the third-party vehicle .glb files from their upstream sources (stdlib only).

  glb.py obj     SRC.obj  OUT.glb                  OBJ (+ the .mtl named by mtllib) -> GLB
  glb.py gltf    SRC.gltf OUT.glb                  .gltf + external/data-URI buffers and images -> one GLB
  glb.py compose SRC.glb  OUT.glb PLACEMENTS NAME  new scene of SRC's meshes placed at translations
  glb.py deps    SRC.obj|SRC.gltf                  list companion files SRC refers to (.mtl, .bin, images)

Geometry is never changed: vertex positions/normals/indices are copied as they are (obj:
re-packed to float32/uint16|uint32, no rescale/recentre; gltf/compose: buffer bytes untouched).
obj: one node+mesh per OBJ object ('o'/'g'), one primitive per material, MTL Kd(+d) as baseColor.
compose: keeps the source's accessors/bufferViews/buffer/materials, keeps only the meshes used,
and replaces nodes/scenes by one node per placement (PLACEMENTS is JSON: NAME -> [{mesh, translation}]).
The JSON chunk is json.dumps(separators=(',',':')) in insertion order, so output is byte-reproducible.
"""
import base64, json, os, struct, sys
from urllib.parse import unquote

def pad(b, c=b'\0'):
    return b + c * (-len(b) % 4)

def read_glb(path):
    d = open(path, 'rb').read()
    jl = struct.unpack_from('<I', d, 12)[0]
    bl = struct.unpack_from('<I', d, 20 + jl)[0]
    return json.loads(d[20:20 + jl]), d[28 + jl:28 + jl + bl]

def write_glb(g, blob, path):
    js, blob = pad(json.dumps(g, separators=(',', ':')).encode(), b' '), pad(bytes(blob))
    with open(path, 'wb') as f:
        f.write(struct.pack('<III', 0x46546C67, 2, 28 + len(js) + len(blob)))
        f.write(struct.pack('<II', len(js), 0x4E4F534A) + js + struct.pack('<II', len(blob), 0x004E4942) + blob)

def parse_mtl(path):
    mats, cur = {}, None
    if not os.path.exists(path): return mats
    for p in (l.split() for l in open(path, encoding='utf-8', errors='replace')):
        if not p: continue
        if p[0] == 'newmtl': cur = ' '.join(p[1:]); mats[cur] = {'Kd': [0.8, 0.8, 0.8], 'd': 1.0}
        elif p[0] == 'Kd' and cur: mats[cur]['Kd'] = [float(x) for x in p[1:4]]
        elif p[0] == 'd' and cur: mats[cur]['d'] = float(p[1])
    return mats

def obj(src, out):
    V, N, objs, cur, mtl, mtllib = [], [], [], None, None, None
    for p in (l.split() for l in open(src, encoding='utf-8', errors='replace')):
        if not p: continue
        if p[0] == 'v': V.append(tuple(float(x) for x in p[1:4]))
        elif p[0] == 'vn': N.append(tuple(float(x) for x in p[1:4]))
        elif p[0] in ('o', 'g'):
            if p[0] == 'g' and cur is not None and cur['name'] == ' '.join(p[1:]): continue
            cur = {'name': ' '.join(p[1:]) or 'obj', 'prims': {}}; objs.append(cur)
        elif p[0] == 'usemtl': mtl = ' '.join(p[1:])
        elif p[0] == 'mtllib': mtllib = ' '.join(p[1:])
        elif p[0] == 'f':
            idx = []
            for w in p[1:]:
                s = w.split('/'); vi = int(s[0]); ni = None
                if len(s) >= 3 and s[2]: ni = int(s[2]); ni = ni - 1 if ni > 0 else len(N) + ni
                idx.append((vi - 1 if vi > 0 else len(V) + vi, ni))
            if cur is None: cur = {'name': 'default', 'prims': {}}; objs.append(cur)
            tris = cur['prims'].setdefault(mtl, [])
            tris.extend((idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1))  # fan
    mats = parse_mtl(os.path.join(os.path.dirname(src), mtllib)) if mtllib else {}
    buf, views, accs, meshes, nodes, gmats, matidx = bytearray(), [], [], [], [], [], {}
    def view(data, target):
        buf.extend(b'\0' * (-len(buf) % 4))
        views.append({'buffer': 0, 'byteOffset': len(buf), 'byteLength': len(data), 'target': target})
        buf.extend(data); return len(views) - 1
    def acc(a): accs.append(a); return len(accs) - 1
    for o in objs:
        prims = []
        for m, tris in o['prims'].items():
            if not tris: continue
            has_n = all(c[1] is not None for t in tris for c in t)
            remap, pos, nor, ind = {}, [], [], []
            for c in (c for t in tris for c in t):
                key = c if has_n else (c[0], None)
                if key not in remap:
                    remap[key] = len(pos); pos.append(V[c[0]])
                    if has_n: nor.append(N[c[1]])
                ind.append(remap[key])
            attrs = {'POSITION': acc({'bufferView': view(b''.join(struct.pack('<3f', *v) for v in pos), 34962),
                'componentType': 5126, 'count': len(pos), 'type': 'VEC3',
                'min': [min(v[i] for v in pos) for i in range(3)], 'max': [max(v[i] for v in pos) for i in range(3)]})}
            if has_n:
                attrs['NORMAL'] = acc({'bufferView': view(b''.join(struct.pack('<3f', *v) for v in nor), 34962),
                                       'componentType': 5126, 'count': len(nor), 'type': 'VEC3'})
            big = len(pos) > 65535
            prim = {'attributes': attrs, 'indices': acc({'bufferView': view(b''.join(struct.pack('<I' if big else '<H', i) for i in ind), 34963),
                    'componentType': 5125 if big else 5123, 'count': len(ind), 'type': 'SCALAR'}), 'mode': 4}
            if m is not None:
                if m not in matidx:
                    mm = mats.get(m, {'Kd': [0.8, 0.8, 0.8], 'd': 1.0})
                    gmats.append({'name': m, 'pbrMetallicRoughness': {'baseColorFactor': mm['Kd'][:3] + [mm['d']],
                                  'metallicFactor': 0.0, 'roughnessFactor': 0.8}})
                    matidx[m] = len(gmats) - 1
                prim['material'] = matidx[m]
            prims.append(prim)
        if prims:
            meshes.append({'name': o['name'], 'primitives': prims}); nodes.append({'name': o['name'], 'mesh': len(meshes) - 1})
    nodes.append({'name': os.path.splitext(os.path.basename(src))[0], 'children': list(range(len(nodes)))})
    g = {'asset': {'version': '2.0', 'generator': 'mvpcc obj2glb.py (pure python, geometry unchanged)'}, 'scene': 0,
         'scenes': [{'nodes': [len(nodes) - 1]}], 'nodes': nodes, 'meshes': meshes, 'accessors': accs,
         'bufferViews': views, 'buffers': [{'byteLength': len(pad(buf))}]}
    if gmats: g['materials'] = gmats
    write_glb(g, buf, out)

def gltf(src, out):
    base = os.path.dirname(os.path.abspath(src))
    def load(uri):
        if uri.startswith('data:'): return base64.b64decode(uri.split(',', 1)[1])
        return open(os.path.join(base, unquote(uri)), 'rb').read()
    g = json.load(open(src, encoding='utf-8'))
    blob, offsets = b'', []
    for b in g.get('buffers', []):  # concatenate all buffers, each 4-aligned
        offsets.append(len(blob)); blob = pad(blob + (load(b['uri']) if 'uri' in b else b''))
    for bv in g.get('bufferViews', []):
        bv['byteOffset'] = bv.get('byteOffset', 0) + offsets[bv.get('buffer', 0)]; bv['buffer'] = 0
    for img in g.get('images', []):  # embed images as extra bufferViews
        if 'uri' not in img: continue
        data = load(img['uri'])
        if 'mimeType' not in img:
            img['mimeType'] = 'image/png' if img['uri'].lower().endswith('.png') or data[:4] == b'\x89PNG' else 'image/jpeg'
        del img['uri']
        g.setdefault('bufferViews', []).append({'buffer': 0, 'byteOffset': len(blob), 'byteLength': len(data)})
        img['bufferView'] = len(g['bufferViews']) - 1; blob = pad(blob + data)
    g['buffers'] = [{'byteLength': len(blob)}]
    write_glb(g, blob, out)

def compose(src, out, placements, name):
    g, blob = read_glb(src)
    names, used, nodes = [m['name'] for m in g['meshes']], [], []
    for p in json.load(open(placements, encoding='utf-8'))[name]:
        mi = names.index(p['mesh'])
        if mi not in used: used.append(mi)
        nodes.append({'name': p['mesh'], 'mesh': used.index(mi), 'translation': p['translation']})
    g['meshes'] = [g['meshes'][i] for i in used]
    g['nodes'], g['scenes'], g['scene'] = nodes, [{'name': 'Scene', 'nodes': list(range(len(nodes)))}], 0
    g.pop('animations', None); g.pop('skins', None)
    write_glb(g, blob, out)

def deps(src):
    if src.endswith('.obj'):
        for p in (l.split() for l in open(src, encoding='utf-8', errors='replace')):
            if p and p[0] == 'mtllib': print(' '.join(p[1:]))
    else:
        g = json.load(open(src, encoding='utf-8'))
        for x in g.get('buffers', []) + g.get('images', []):
            if 'uri' in x and not x['uri'].startswith('data:'): print(unquote(x['uri']))

if __name__ == '__main__':
    cmds = {'obj': (obj, 2), 'gltf': (gltf, 2), 'compose': (compose, 4), 'deps': (deps, 1)}
    if len(sys.argv) < 2 or sys.argv[1] not in cmds or len(sys.argv) != 2 + cmds[sys.argv[1]][1]:
        sys.exit(__doc__)
    cmds[sys.argv[1]][0](*sys.argv[2:])
