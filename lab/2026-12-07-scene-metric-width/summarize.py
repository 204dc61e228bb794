#!/usr/bin/env python3
"""Per-vehicle plane offsets and F1 (street vs cut out) of scene_detection --vehicles CSVs."""
import csv,statistics as st,sys
from collections import Counter
for f in sys.argv[1:]:
    r=list(csv.DictReader(open(f)))
    offs=[float(x['plane_off_share']) for x in r if x['plane_off_share']]
    f1=[float(x['f1_street_vs_cut_out']) for x in r]
    print(f,len(r),'planes',len(offs),'median off %.4f'%st.median(offs),'>0.5%%: %d >1%%: %d >2%%: %d'%(sum(o>0.005 for o in offs),sum(o>0.01 for o in offs),sum(o>0.02 for o in offs)),'F1 median %.3f, >=0.98: %d, <0.9: %d'%(st.median(f1),sum(x>=0.98 for x in f1),sum(x<0.9 for x in f1)))
    print('  fits',Counter(x['fit'] for x in r))
    for cat in sorted(set(x["category"] for x in r if x["plane_off_share"])):
        o=[float(x['plane_off_share']) for x in r if x['plane_off_share'] and x['category']==cat]
        print('   %-10s n=%2d median %.4f max %.4f >0.5%%: %d'%(cat,len(o),st.median(o),max(o),sum(v>0.005 for v in o)))
