"""Record the shipped weights' eval generative figures over every measured seed under
metrics.generative_seeds in weights/manifest.json (metrics.generative stays the seed-12345 run
that eval generative --write-manifest wrote). Run from the repository root:
    python3 docs/eval/single_schedule/pool_seeds.py"""
import json

D = 'docs/eval/single_schedule/'
files = [D + f'gen_s14r_{s}.json' for s in (12345, 1, 2, 3, 4, 5, 6)]
seeds, hits, n = [], 0, 0
for f in files:
    d = json.load(open(f))
    c, u = d['conditional'], d['unconditional']
    h = sum(x['hits'] for x in c['categories'])
    k = sum(x['samples'] for x in c['categories'])
    hits, n = hits + h, n + k
    seeds.append({'seed': d['seed'], 'category_accuracy': c['accuracy'], 'hits': h, 'samples': k,
                  'one_nna': u['one_nna'], 'mmd': u['mmd'], 'cov': u['cov'],
                  'valid_rate': u['valid_rate'], 'file': f})
p = 'weights/manifest.json'
m = json.load(open(p))
m['metrics']['generative_seeds'] = {
    'command': 'physnap eval generative --weights weights --data data/train --samples 48 '
               '--refs 48 --per-category 4 --states 4 --points 256 --seed SEED',
    'seeds': seeds,
    'category_accuracy_pooled': hits / n,
    'category_hits_pooled': hits,
    'category_samples_pooled': n,
    'one_nna_max': max(s['one_nna'] for s in seeds),
    'target_category_accuracy': 0.8,
    'target_one_nna': 0.75,
}
open(p, 'w').write(json.dumps(m, indent=2, ensure_ascii=False).replace('1e-08', '1e-8') + '\n')
print(f"pooled category accuracy {hits}/{n} = {hits / n:.3f}, max 1-NNA {m['metrics']['generative_seeds']['one_nna_max']:.3f}")
