#!/usr/bin/env python3
"""Binary FBX (7.x) -> GLB, stdlib only, in the style of scripts/thirdparty/glb.py.

  fbx2glb.py SRC.fbx OUT.glb

Geometry is not changed: each FBX Geometry's vertex positions (and ByPolygonVertex normals, if present)
are copied as float32; polygons are fan-triangulated; one glTF node+mesh per FBX Model, one primitive
per material (Material DiffuseColor as baseColor).  The FBX node hierarchy is kept: each node gets
its local matrix T * PreRotation * R(Euler XYZ) * S, and one root node carries the unit scale
(GlobalSettings UnitScaleFactor/100, i.e. FBX centimetres -> metres) and, if UpAxis is Z, the
Z-up -> Y-up rotation.  Output is byte-reproducible (json.dumps with separators, insertion order).
"""
import json, math, struct, sys, zlib

def pad(b, c=b'\0'):
    return b + c * (-len(b) % 4)

def write_glb(g, blob, path):
    js, blob = pad(json.dumps(g, separators=(',', ':')).encode(), b' '), pad(bytes(blob))
    with open(path, 'wb') as f:
        f.write(struct.pack('<III', 0x46546C67, 2, 28 + len(js) + len(blob)))
        f.write(struct.pack('<II', len(js), 0x4E4F534A) + js + struct.pack('<II', len(blob), 0x004E4942) + blob)

ARR = {'f': ('f', 4), 'd': ('d', 8), 'l': ('q', 8), 'i': ('i', 4), 'b': ('B', 1)}
SCAL = {'Y': ('h', 2), 'C': ('B', 1), 'I': ('i', 4), 'F': ('f', 4), 'D': ('d', 8), 'L': ('q', 8)}

def parse(data):
    assert data[:20] == b'Kaydara FBX Binary  ', 'not a binary FBX'
    ver = struct.unpack_from('<I', data, 23)[0]
    wide = ver >= 7500
    hdr, fmt = (25, '<QQQB') if wide else (13, '<IIIB')
    def node(o):
        end, nprop, plen, nlen = struct.unpack_from(fmt, data, o)
        if end == 0: return None, o + hdr
        name = data[o + hdr:o + hdr + nlen].decode('latin-1'); p = o + hdr + nlen
        props = []
        for _ in range(nprop):
            t = chr(data[p]); p += 1
            if t in SCAL:
                c, n = SCAL[t]; props.append(struct.unpack_from('<' + c, data, p)[0]); p += n
            elif t in ARR:
                ln, enc, cl = struct.unpack_from('<III', data, p); p += 12
                raw = data[p:p + cl]; p += cl
                if enc == 1: raw = zlib.decompress(raw)
                c, n = ARR[t]; props.append(list(struct.unpack('<%d%s' % (ln, c), raw[:ln * n])))
            elif t in 'SR':
                ln = struct.unpack_from('<I', data, p)[0]; p += 4
                v = data[p:p + ln]; p += ln
                props.append(v.decode('utf-8', 'replace') if t == 'S' else v)
            else:
                raise ValueError('unknown FBX property type %r' % t)
        kids = []
        while p < end:
            k, p = node(p)
            if k is None: break
            kids.append(k)
        return (name, props, kids), end
    top, o = [], 27
    while o < len(data) - hdr:
        n, o = node(o)
        if n is None: break
        top.append(n)
    return top

def child(n, name):
    for k in n[2]:
        if k[0] == name: return k
    return None

def p70(n):
    out = {}
    pp = child(n, 'Properties70')
    for k in (pp[2] if pp else []):
        if k[0] == 'P': out[k[1][0]] = k[1][4:]
    return out

def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]

def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    m = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    i, j = {'x': (1, 2), 'y': (2, 0), 'z': (0, 1)}[axis]
    m[i][i], m[i][j], m[j][i], m[j][j] = c, -s, s, c
    return m

def euler_xyz(r):  # FBX eEulerXYZ: X applied first -> Rz * Ry * Rx
    return matmul(rot('z', r[2]), matmul(rot('y', r[1]), rot('x', r[0])))

def local_matrix(props):
    t = props.get('Lcl Translation', [0, 0, 0]); r = props.get('Lcl Rotation', [0, 0, 0])
    s = props.get('Lcl Scaling', [1, 1, 1]); pre = props.get('PreRotation', [0, 0, 0])
    if int((props.get('RotationOrder') or [0])[0]) != 0: raise ValueError('only RotationOrder XYZ supported')
    T = [[1, 0, 0, t[0]], [0, 1, 0, t[1]], [0, 0, 1, t[2]], [0, 0, 0, 1]]
    S = [[s[0], 0, 0, 0], [0, s[1], 0, 0], [0, 0, s[2], 0], [0, 0, 0, 1]]
    return matmul(T, matmul(euler_xyz(pre), matmul(euler_xyz(r), S)))

def colmajor(m):
    return [round(m[i][j], 9) + 0.0 for j in range(4) for i in range(4)]

def convert(src, out):
    top = {n[0]: n for n in parse(open(src, 'rb').read())}
    gs = p70(top['GlobalSettings'])
    unit = float((gs.get('UnitScaleFactor') or [1.0])[0]); up = int((gs.get('UpAxis') or [1])[0])
    objs = {}
    for n in top['Objects'][2]:
        objs[n[1][0]] = n
    parent, geo_of, mats_of = {}, {}, {}
    for c in top['Connections'][2]:
        if c[1][0] != 'OO': continue
        ch, pa = objs.get(c[1][1]), objs.get(c[1][2])
        if ch is None: continue
        if ch[0] == 'Model' and (pa is None or pa[0] == 'Model'): parent[c[1][1]] = c[1][2] if pa else 0
        elif ch[0] == 'Geometry' and pa is not None: geo_of[c[1][2]] = c[1][1]
        elif ch[0] == 'Material' and pa is not None: mats_of.setdefault(c[1][2], []).append(c[1][1])
    models = [i for i, n in objs.items() if n[0] == 'Model']
    buf, views, accs, meshes, nodes, gmats, matidx, nodeidx = bytearray(), [], [], [], [], [], {}, {}
    def view(data, target):
        buf.extend(b'\0' * (-len(buf) % 4))
        views.append({'buffer': 0, 'byteOffset': len(buf), 'byteLength': len(data), 'target': target})
        buf.extend(data); return len(views) - 1
    def acc(a): accs.append(a); return len(accs) - 1
    for mid in models:
        m = objs[mid]; props = p70(m)
        for k in ('GeometricTranslation', 'GeometricRotation', 'RotationPivot', 'ScalingPivot', 'PostRotation'):
            if k in props and any(abs(v) > 1e-9 for v in props[k][:3]): raise ValueError('%s not supported' % k)
        node = {'name': m[1][1].split('\x00')[0], 'matrix': colmajor(local_matrix(props))}
        if node['matrix'] == colmajor([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]): del node['matrix']
        gid = geo_of.get(mid)
        if gid is not None:
            g = objs[gid]
            V = child(g, 'Vertices')[1][0]; P = child(g, 'PolygonVertexIndex')[1][0]
            nl = child(g, 'LayerElementNormal'); N = None
            if nl and child(nl, 'MappingInformationType')[1][0] == 'ByPolygonVertex':
                N = child(nl, 'Normals')[1][0]
                if child(nl, 'ReferenceInformationType')[1][0] == 'IndexToDirect':
                    ni = child(nl, 'NormalsIndex')[1][0]; N = [c for i in ni for c in N[3 * i:3 * i + 3]]
            ml = child(g, 'LayerElementMaterial'); pm = None
            if ml:
                pm = child(ml, 'Materials')[1][0]
                if child(ml, 'MappingInformationType')[1][0] == 'AllSame': pm = None if not pm else [pm[0]]
            mlist = mats_of.get(mid, [])
            prims, poly, corner, k = {}, [], 0, 0
            for v in P:
                poly.append((v if v >= 0 else ~v, corner)); corner += 1
                if v < 0:
                    mi = (pm[k] if len(pm) > 1 else pm[0]) if pm else 0
                    tris = prims.setdefault(mi, [])
                    tris.extend((poly[0], poly[j], poly[j + 1]) for j in range(1, len(poly) - 1))
                    poly, k = [], k + 1
            gprims = []
            for mi, tris in prims.items():
                remap, pos, nor, ind = {}, [], [], []
                for c in (c for t in tris for c in t):
                    key = (c[0], tuple(round(x, 6) for x in N[3 * c[1]:3 * c[1] + 3])) if N else (c[0],)
                    if key not in remap:
                        remap[key] = len(pos); pos.append(tuple(V[3 * c[0]:3 * c[0] + 3]))
                        if N: nor.append(key[1])
                    ind.append(remap[key])
                attrs = {'POSITION': acc({'bufferView': view(b''.join(struct.pack('<3f', *v) for v in pos), 34962),
                    'componentType': 5126, 'count': len(pos), 'type': 'VEC3',
                    'min': [struct.unpack('<f', struct.pack('<f', min(v[i] for v in pos)))[0] for i in range(3)],
                    'max': [struct.unpack('<f', struct.pack('<f', max(v[i] for v in pos)))[0] for i in range(3)]})}
                if N:
                    attrs['NORMAL'] = acc({'bufferView': view(b''.join(struct.pack('<3f', *v) for v in nor), 34962),
                                           'componentType': 5126, 'count': len(nor), 'type': 'VEC3'})
                big = len(pos) > 65535
                prim = {'attributes': attrs, 'indices': acc({'bufferView': view(b''.join(struct.pack('<I' if big else '<H', i) for i in ind), 34963),
                        'componentType': 5125 if big else 5123, 'count': len(ind), 'type': 'SCALAR'}), 'mode': 4}
                if mi < len(mlist):
                    matid = mlist[mi]
                    if matid not in matidx:
                        mp = p70(objs[matid]); kd = list(mp.get('DiffuseColor', [0.8, 0.8, 0.8]))[:3]
                        gmats.append({'name': objs[matid][1][1].split('\x00')[0], 'pbrMetallicRoughness': {
                            'baseColorFactor': [float(x) for x in kd] + [1.0], 'metallicFactor': 0.0, 'roughnessFactor': 0.8}})
                        matidx[matid] = len(gmats) - 1
                    prim['material'] = matidx[matid]
                gprims.append(prim)
            if gprims:
                meshes.append({'name': node['name'], 'primitives': gprims}); node['mesh'] = len(meshes) - 1
        nodeidx[mid] = len(nodes); nodes.append(node)
    for mid in models:
        pa = parent.get(mid, 0)
        if pa and pa in nodeidx: nodes[nodeidx[pa]].setdefault('children', []).append(nodeidx[mid])
    roots = [nodeidx[m] for m in models if not (parent.get(m, 0) and parent.get(m, 0) in nodeidx)]
    s = unit / 100.0
    R = rot('x', -90) if up == 2 else [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    root = {'name': src.rsplit('/', 1)[-1].rsplit('.', 1)[0], 'children': roots,
            'matrix': colmajor(matmul(R, [[s, 0, 0, 0], [0, s, 0, 0], [0, 0, s, 0], [0, 0, 0, 1]]))}
    nodes.append(root)
    g = {'asset': {'version': '2.0', 'generator': 'mvpcc fbx2glb.py (pure python, geometry unchanged)'}, 'scene': 0,
         'scenes': [{'nodes': [len(nodes) - 1]}], 'nodes': nodes, 'meshes': meshes, 'accessors': accs,
         'bufferViews': views, 'buffers': [{'byteLength': len(pad(buf))}]}
    if gmats: g['materials'] = gmats
    write_glb(g, buf, out)

if __name__ == '__main__':
    if len(sys.argv) != 3: sys.exit(__doc__)
    convert(sys.argv[1], sys.argv[2])
