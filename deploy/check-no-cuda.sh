#!/bin/sh
# Fails when the venv given as $1 holds a CUDA build of torch or any CUDA
# library (the nvidia-* wheels, libcudart, libcublas, libcudnn ...).
set -eu
venv=$1
"$venv/bin/python" - <<'PY'
import sys
import torch
cuda = torch.version.cuda
print(f"torch {torch.__version__}, CUDA: {cuda}")
if cuda is not None or torch.backends.cudnn.version() is not None:
    sys.exit("error: a CUDA build of torch is installed; build with torch's CPU index "
             "(TORCH_INDEX) or a wheelhouse holding the CPU wheel")
PY
found=$(find "$venv" \( -iname 'libcu*.so*' -o -iname 'libnv*.so*' -o -iname 'libnccl*' \
        -o -path '*/site-packages/nvidia' -o -iname 'nvidia_*.dist-info' \) -print | head -5)
if [ -n "$found" ]; then
    echo "error: CUDA libraries in the image:" >&2
    echo "$found" >&2
    exit 1
fi
echo "no CUDA library in $venv"
