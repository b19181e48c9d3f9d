"""Average the F32 tensors of safetensors files with identical layouts (weight averaging of
checkpoints along one training run: SWA over the ends of cosine cycles).
Usage: soup.py OUT IN1 IN2 [...]"""
import array, json, struct, sys
out, ins = sys.argv[1], sys.argv[2:]
blobs = [open(p, 'rb').read() for p in ins]
n = struct.unpack('<Q', blobs[0][:8])[0]
header = blobs[0][8:8 + n]
for b in blobs[1:]:
    assert b[:8 + n] == blobs[0][:8 + n], "layouts differ"
h = json.loads(header)
assert all(v['dtype'] == 'F32' for k, v in h.items() if k != '__metadata__')
acc = array.array('f', blobs[0][8 + n:])
for b in blobs[1:]:
    a = array.array('f', b[8 + n:])
    for i in range(len(acc)):
        acc[i] += a[i]
k = float(len(blobs))
for i in range(len(acc)):
    acc[i] /= k
open(out, 'wb').write(blobs[0][:8 + n] + acc.tobytes())
