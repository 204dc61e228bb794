#!/usr/bin/env python3
"""docs/paper.md's Tables 5 and 6 from results.csv (ours) beside the paper's cells.
Usage: table.py results.csv"""
import csv, sys

PAPER_VIEWS = {  # colour PSNR, SSIM, MAE, CD x1e-3, F1 %
    3: (25.03, 0.9013, 0.0860, 6.937, 81.31), 4: (24.95, 0.8969, 0.0892, 6.585, 83.07),
    5: (22.67, 0.7803, 0.1768, 7.45, 80.67), 6: (21.44, 0.7063, 0.2340, 8.28, 76.03),
    7: (20.11, 0.6367, 0.2768, 11.214, 65.08), 8: (19.42, 0.5908, 0.2968, 9.19, 73.16),
    10: (18.40, 0.5342, 0.3689, 13.697, 63.54)}
PAPER_FUSION = {('early', 'xyz'): (5.735, 87.33), ('early', 'xyzrgb'): (11.792, 69.29),
                ('late', 'xyz'): (5.315, 89.04), ('late', 'xyzrgb'): (6.585, 83.07)}
rows = {r['row']: r for r in csv.DictReader(open(sys.argv[1]))}

def ours(r):
    cd_f1 = f"{1e3 * float(r['cd_l1']):.2f} / {100 * float(r['f1']):.2f}"
    geo = f"{float(r['geometry_psnr']):.2f} / {float(r['geometry_ssim']):.3f} / {float(r['geometry_mae']):.4f}"
    col = (f"{float(r['color_psnr']):.2f} / {float(r['color_ssim']):.3f} / {float(r['color_mae']):.4f}"
           if r['color_psnr'] else '—')
    return cd_f1, geo, col

print('| views | the paper: colour PSNR / SSIM / MAE | the paper: CD / F1 | ours: CD / F1 | ours: geometry PSNR / SSIM / MAE | ours: colour PSNR / SSIM / MAE |')
print('|---|---|---|---|---|---|')
by_views = {int(r['views']): r for r in rows.values() if r['fusion'] == 'late' and r['channels'] == 'xyzrgb'}
for v, p in PAPER_VIEWS.items():
    cells = ours(by_views[v]) if v in by_views else ('—', '—', '—')
    print(f"| {v} | {p[0]:.2f} / {p[1]:.4f} / {p[2]:.4f} | {p[3]} / {p[4]:.2f} | {' | '.join(cells)} |")
print()
print('| fusion | channels | the paper: CD / F1 | ours: CD / F1 | ours: geometry PSNR / SSIM / MAE | ours: colour PSNR / SSIM / MAE |')
print('|---|---|---|---|---|---|')
for (fusion, channels), p in PAPER_FUSION.items():
    r = [r for r in rows.values() if r['fusion'] == fusion and r['channels'] == channels and r['views'] == '4']
    cells = ours(r[0]) if r else ('not run', '', '')
    print(f"| {fusion} | {'XYZ' if channels == 'xyz' else 'XYZRGB'} | {p[0]} / {p[1]:.2f} | {' | '.join(cells)} |")
