"""Install candidate fcg2 as the shipped weights: its shape prior (the ws10 decoder), codebook
(fitted codes) and denoiser, its manifest (which already carries the ws10 decoder's lineage:
shape_base and shape_cycles, added by hand in session 46 when the codes were made) with the
metrics `eval shape --write-manifest` and `eval generative --write-manifest` wrote into it, and
its eval generative figures at every measured seed under metrics.generative_seeds
(metrics.generative stays the seed-12345 run that --write-manifest wrote). The manifest shipped
before (lg2) is kept as docs/eval/code_gain/previous_manifest.json. Run from the repository root:
    python3 docs/eval/code_gain/ship.py CANDIDATE_WEIGHTS_DIR"""
import hashlib
import json
import shutil
import sys

src = sys.argv[1]
D = 'docs/eval/code_gain/'
sha = lambda p: hashlib.sha256(open(p, 'rb').read()).hexdigest()
FILES = {'shape_prior': 'shape_prior.safetensors', 'codebook': 'codebook.safetensors',
         'denoiser': 'denoiser.safetensors'}
m = json.load(open(f'{src}/manifest.json'))
for key, f in FILES.items():
    assert m[key]['sha256'] == sha(f'{src}/{f}'), f'{f} does not match its manifest'
assert m['training']['diffusion']['code_gain'] == 2.0, 'not the code-gain-2 denoiser'
assert len(m['training']['shape_cycles']) == 2 and m['training']['shape']['config']['wrong_side'] == 10
shape = m['metrics']['shape']
assert shape['parts'] == 64 and shape['resolution'] == 64 and shape['encoding']['views'] == 16
gen = m['metrics']['generative']
assert gen['seed'] == 12345 and gen['unconditional']['samples'] == 48

seeds, hits, n = [], 0, 0
for s in (12345, 1, 2, 3, 4, 5, 6, 7, 8):
    f = D + f'gen32_fcg2_{s}.json'
    d = json.load(open(f))
    c = d['conditional']
    h = sum(x['hits'] for x in c['categories'])
    k = sum(x['samples'] for x in c['categories'])
    hits, n = hits + h, n + k
    row = {'seed': d['seed'], 'category_accuracy': c['accuracy'], 'hits': h, 'samples': k,
           'file': f}
    # Seeds 12345 and 1 also ran 48 + 48 (genfull_*): the same 52 category samples, and the
    # unconditional figures; seeds 2-8 ran the category samples only (--samples 2 --refs 2).
    if s in (12345, 1):
        full = json.load(open(D + f'genfull_fcg2_{s}.json'))
        assert full['conditional']['accuracy'] == c['accuracy'], f'seed {s}: runs disagree'
        u = full['unconditional']
        row.update(one_nna=u['one_nna'], mmd=u['mmd'], cov=u['cov'], valid_rate=u['valid_rate'],
                   file_unconditional=D + f'genfull_fcg2_{s}.json')
        if s == 12345:
            # --write-manifest's run repeats the seed-12345 run: sampling is deterministic.
            assert gen['unconditional']['one_nna'] == u['one_nna'], 'seed 12345 not reproduced'
            assert gen['conditional']['accuracy'] == c['accuracy'], 'seed 12345 not reproduced'
    seeds.append(row)
m['metrics']['generative_seeds'] = {
    'command': 'physnap eval generative --weights weights --data data/train --samples 48 '
               '--refs 48 --per-category 4 --states 4 --points 256 --seed SEED (seeds 2-8: '
               '--samples 2 --refs 2, the category samples only)',
    'seeds': seeds,
    'category_accuracy_pooled': hits / n,
    'category_hits_pooled': hits,
    'category_samples_pooled': n,
    'one_nna_max': max(s['one_nna'] for s in seeds if 'one_nna' in s),
    'target_category_accuracy': 0.8,
    'target_one_nna': 0.75,
}
shutil.copyfile('weights/manifest.json', D + 'previous_manifest.json')
for f in FILES.values():
    shutil.copyfile(f'{src}/{f}', f'weights/{f}')
shutil.copyfile(f'{src}/eval_generative.json', 'weights/eval_generative.json')
open('weights/manifest.json', 'w').write(
    json.dumps(m, indent=2, ensure_ascii=False).replace('1e-08', '1e-8') + '\n')
print(f"shape IoU {shape['mean_iou']:.3f}; pooled category accuracy {hits}/{n} = {hits / n:.3f}; "
      f"max 1-NNA {m['metrics']['generative_seeds']['one_nna_max']:.3f}")
