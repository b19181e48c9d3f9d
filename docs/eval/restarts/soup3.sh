#!/usr/bin/env bash
# Session 43: candidate soup3 = the uniform average of the EMA denoisers at the ends of three
# cosine cycles of one run (s14r at 18,000 steps, s22 at 22,000, s26 at 26,000; stochastic weight
# averaging over cycle ends), on s14r's shape prior and codebook; the manifest's denoiser sha256
# is rewritten so the weights load. Then eval generative at seeds 12345 and 1 (gen.sh).
set -euo pipefail
cd /work/exp/s43
rm -rf soup3 && mkdir soup3 && cp -r /work/exp/s40/s14r/weights soup3/weights
rm soup3/weights/denoiser_raw.safetensors soup3/weights/checkpoint.json
python3 soup.py soup3/weights/denoiser.safetensors /work/exp/s40/s14r/weights/denoiser.safetensors \
  s22/weights/denoiser.safetensors s26/weights/denoiser.safetensors
sha=$(sha256sum soup3/weights/denoiser.safetensors | cut -d' ' -f1)
sed -i "s/1c70cd1517df23946b300a85b27a3b9e589823991b216070d6fe3991321f7a5c/$sha/g" soup3/weights/manifest.json
./gen.sh soup3 12345 1
