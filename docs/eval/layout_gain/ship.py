"""Install candidate lg2 as the shipped weights: its denoiser (the shape prior and codebook are
the shipped files, byte for byte), its manifest with the shipped prior's lineage (shape_base,
shape_cycles: the candidate was trained on the shipped codes, made before `train encode`
recorded a lineage) and its eval generative figures at every measured seed under
metrics.generative_seeds (metrics.generative stays the seed-12345 run that eval generative
--write-manifest wrote). Run from the repository root:
    python3 docs/eval/layout_gain/ship.py CANDIDATE_WEIGHTS_DIR"""
import hashlib
import json
import shutil
import sys

src = sys.argv[1]
D = 'docs/eval/layout_gain/'
sha = lambda p: hashlib.sha256(open(p, 'rb').read()).hexdigest()
for f in ('shape_prior.safetensors', 'codebook.safetensors'):
    assert sha(f'{src}/{f}') == sha(f'weights/{f}'), f'{f} differs from the shipped one'
old = json.load(open('weights/manifest.json'))
m = json.load(open(f'{src}/manifest.json'))
assert m['denoiser']['sha256'] == sha(f'{src}/denoiser.safetensors')
for k in ('shape_base', 'shape_cycles'):
    m['training'][k] = old['training'][k]
m['training']['shape'].pop('encoded_from', None)

seeds, hits, n = [], 0, 0
for s in (12345, 1, 2, 3, 4, 5, 6, 7, 8):
    f = D + f'gen_lg2_{s}.json'
    d = json.load(open(f))
    c, u = d['conditional'], d['unconditional']
    h = sum(x['hits'] for x in c['categories'])
    k = sum(x['samples'] for x in c['categories'])
    hits, n = hits + h, n + k
    row = {'seed': d['seed'], 'category_accuracy': c['accuracy'], 'hits': h, 'samples': k,
           'file': f}
    # Seeds 2-8 ran the 52 category samples only (--samples 2 --refs 2): no unconditional figures.
    if s in (12345, 1):
        row.update(one_nna=u['one_nna'], mmd=u['mmd'], cov=u['cov'], valid_rate=u['valid_rate'])
    seeds.append(row)
m['metrics']['generative_seeds'] = {
    'command': 'physnap eval generative --weights weights --data data/train --samples 48 '
               '--refs 48 --per-category 4 --states 4 --points 256 --seed SEED '
               '(seeds 2-8: --samples 2 --refs 2, the category samples only)',
    'seeds': seeds,
    'category_accuracy_pooled': hits / n,
    'category_hits_pooled': hits,
    'category_samples_pooled': n,
    'one_nna_max': max(s['one_nna'] for s in seeds if 'one_nna' in s),
    'target_category_accuracy': 0.8,
    'target_one_nna': 0.75,
}
shutil.copyfile(f'{src}/denoiser.safetensors', 'weights/denoiser.safetensors')
shutil.copyfile(D + 'gen_lg2_12345.json', 'weights/eval_generative.json')
open('weights/manifest.json', 'w').write(
    json.dumps(m, indent=2, ensure_ascii=False).replace('1e-08', '1e-8') + '\n')
print(f"pooled category accuracy {hits}/{n} = {hits / n:.3f}, "
      f"max 1-NNA {m['metrics']['generative_seeds']['one_nna_max']:.3f}")
