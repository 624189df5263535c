"""Leave-one-controller-out intervals for the finder's older thresholds,
from instrumented runs (scripts/loco/run.sh) in the folder given (g_*
generator, n_* Neural-Fly): for each rule, the interval of values that
put every labelled case of the groups kept on its right side, with each
group left out in turn, and the left-out group's cases against the rule.
Labels: the generator's concealed effects must be claimed, its others
not; on Neural-Fly the fan flights' wind and drag must be claimed and no
physics on a no-wind flight; rotor drag and the x area must be one
combined finding on the 100 % fan flights (airspeed within about 12 % of
its mean: one line), and the generator's concealed parameters checked
within 15 % must stay apart (pinned pairs and the axial / vertical pair,
whose combination is what is checked, exempt)."""
import json, glob, os, re, sys
PHYS = {'ground_effect','motor_lag','drag','wind','battery_sag'}
def load(path):
    name = os.path.basename(path)[:-4]
    txt = open(path).read()
    js = json.load(open(path[:-4] + '/explain.json'))
    swaps = {}
    for m in re.finditer(r'DBGSWAP (\S+) Some\(\((\w+), ([-\d.e]+)\)\)', txt):
        swaps[m.group(1)] = float(m.group(3))
    cors = [(a, b, float(r)) for a, b, r in re.findall(r'DBGCOR (\S+) (\S+) ([-\d.]+)', txt)]
    sel_stop = [float(x) for x in re.findall(r'DBGSEL stop \S+ ([-\d.]+)', txt)]
    sel_add = [(e, float(x)) for e, x in re.findall(r'DBGSEL add (\S+) ([-\d.]+)', txt)]
    if name.startswith('g_'):
        ctrl, form, case, seed = name[2:].split('-')
        truth = set() if case == 'none' else set(case.split('+'))
        group = 'gen-' + form
    else:
        _, ctrl, flight = name.split('_', 2)
        truth = None if flight != 'nowind' else set()
        group = 'nf-' + ctrl
    return dict(name=name, ctrl=ctrl, group=group, truth=truth, js=js, swaps=swaps,
                cors=cors, stop=sel_stop, add=sel_add, fan=name.startswith('n_') and 'wind' in name and 'nowind' not in name)
R = [load(p) for p in sorted(glob.glob(os.path.join(sys.argv[1] if len(sys.argv) > 1 else '/tmp/loco_rules', '*.txt')))]
eff = lambda r, n: next((e for e in r['js']['effects'] if e['name'] == n), None)

def swap_labels(r):
    """(best calibration recovery, must_stay, effect) for physics judged by the
    swap (a drag riding with a wind is not): the generator's concealed physics
    must stay; every physics on a no-wind flight must not be claimed alone."""
    out = []
    winds = r['js']['wind_speed'] is not None
    for e, rec in r['swaps'].items():
        if e not in PHYS or (e == 'drag' and winds): continue
        if r['name'].startswith('g_'):
            if e in r['truth']: out.append((rec, True, e))
        elif not r['fan']:
            out.append((rec, False, e))
    return out

def pred_labels(r):
    out = []
    for e in r['js']['effects']:
        d = e.get('decision') or {}
        if d.get('kind') not in ('found', 'rejected_by_prediction'): continue
        if d.get('with') is None or d.get('without') is None: continue
        cut = 1 - d['with'] / d['without']
        n = e['name']
        if r['name'].startswith('g_'):
            out.append((cut, n in r['truth'], n))
        elif r['fan'] and n in ('wind', 'drag'):
            out.append((cut, True, n))
        elif not r['fan'] and n in PHYS and not e['same_finding_as'] and d.get('kind') == 'rejected_by_prediction':
            out.append((cut, False, n))
    return out

def cor_labels(r):
    """must-separate: generator pairs of concealed parameters both within 15 %
    (claimed and identified); must-combine: rotor drag with the x area on fan flights."""
    out = []
    exempt = {('drag.1', 'drag.4'), ('com_offset.0', 'com_offset.1')}  # axial/vertical: the truth's combination is checked; CoM pair pinned
    for a, b, rho in r['cors']:
        ea, eb = a.split('.')[0], b.split('.')[0]
        if r['name'].startswith('g_'):
            if ea in r['truth'] and eb in r['truth'] and (a, b) not in exempt and not {a, b} & {'drag.1'}:
                out.append((abs(rho), False, a + '/' + b))
        elif '100wind' in r['name'] and {a, b} == {'drag.0', 'drag.2'}:
            out.append((abs(rho), True, a + '/' + b))
    return out

def interval(items, stay_low=True):
    # items: (value, positive) ; positive means must be >= threshold (claimed / combined)
    lo = max((v for v, pos, *_ in items if not pos), default=float('-inf'))
    hi = min((v for v, pos, *_ in items if pos), default=float('inf'))
    return lo, hi

def report(title, fn, thr, swap=False):
    print(f'## {title} (threshold {thr})')
    groups = sorted({r['group'] for r in R})
    per = {g: [x for r in R if r['group'] == g for x in fn(r)] for g in groups}
    for g in groups:
        it = [(v, p if not swap else not p) for v, p, *_ in per[g]]
        print(f'  {g}: n={len(it)}', 'must pass: smallest %.4g' % min([v for v, p in it if p], default=float('nan')),
              'must not pass: largest %.4g' % max([v for v, p in it if not p], default=float('nan')))
    # leave one NF controller out (generator always in), and one generator form out
    for out in groups:
        rest = [x for g in groups if g != out for x in per[g]]
        lo, hi = interval([(v, p if not swap else not p) for v, p, *_ in rest])
        left = per[out]
        wrong = [(v, n) for v, p, n in left if (v >= thr) != (p if not swap else not p)]
        print(f'  leave {out} out: interval ({lo:.4g}, {hi:.4g}] contains {thr}: {lo < thr <= hi}; left-out on the wrong side of {thr}: {wrong}')
report('PREDICTION_MARGIN: 0.5 s cut of claimed (positive) vs physics/cases not to claim', pred_labels, 0.01)
report('SWAP_RECOVERY: recovery of physics that must stay (positive=stay below) vs swapped on no-wind', swap_labels, 0.9, swap=True)
report('COMBINED_CORRELATION: |rho| must-combine (positive) vs must-separate', cor_labels, 0.9)
# MIN_GAIN: generator only (NF gains are >= 0.03 for everything added)
print('## MIN_GAIN (0.02): clean flights stop gain vs concealed effects added gain')
for g in ('gen-first', 'gen-second'):
    stops = [max(r['stop'] or [0]) for r in R if r['group'] == g and r['truth'] == set()]
    adds = [x for r in R if r['group'] == g and r['truth'] for e, x in r['add'] if e in r['truth']]
    spur = [x for r in R if r['group'] == g and r['truth'] for e, x in r['add'] if e not in r['truth']]
    print(f'  {g}: clean stop gain max {max(stops, default=float("nan")):.4g} (n={len(stops)}); concealed added min {min(adds, default=float("nan")):.4g}; non-concealed added: {sorted(spur)[:5]}')
for g in ('nf-L1', 'nf-indi', 'nf-NF-C'):
    first_wind = [next((x for e, x in r['add'] if e == 'wind'), None) for r in R if r['group'] == g and r['fan']]
    print(f'  {g}: fan flights, the wind\'s first selection gain: min {min(x for x in first_wind if x is not None):.4g}')
