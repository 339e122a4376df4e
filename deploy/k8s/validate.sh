#!/usr/bin/env bash
# Validates deploy/k8s offline: renders the kustomization, then checks every object
#   1. against the Kubernetes OpenAPI schemas (kubernetes-validate from PyPI, --strict: unknown
#      fields are errors) for each version in K8S_VERSIONS (default 1.27.0, the first with
#      native gRPC probes GA, 1.32.0 and 1.37.0);
#   2. with validate.py check: what a schema cannot see (selectors, ports, probes against the
#      services the .proto files declare, the HPA's target, the orchestrator's addresses).
# Rendering: `kubectl kustomize` (or `kustomize build`) when the machine has one, and then also
# validate.py's own rendering, which must give the same objects; without either, validate.py's
# rendering alone (it implements the kustomization keys used here and refuses any other).
# Exits non-zero on any invalid object. Needs no cluster and no network but PyPI (once).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
t0=$(date +%s.%N)
versions=${K8S_VERSIONS:-1.27.0 1.32.0 1.37.0}

if ! python3 -c 'import kubernetes_validate, yaml' 2>/dev/null; then
    python3 -m pip install --quiet 'kubernetes-validate==1.37.0' pyyaml
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/glint-k8s.XXXXXX")
trap 'rm -rf "$out"' EXIT
python3 "$here/validate.py" render "$here" >"$out/fallback.yaml"
if command -v kubectl >/dev/null && kubectl kustomize "$here" >"$out/rendered.yaml" 2>"$out/kustomize.err"; then
    renderer="kubectl kustomize ($(kubectl version --client 2>/dev/null | tr '\n' ' ' | sed 's/ *$//'))"
elif command -v kustomize >/dev/null && kustomize build "$here" >"$out/rendered.yaml" 2>"$out/kustomize.err"; then
    renderer="kustomize build ($(kustomize version 2>/dev/null | head -1))"
else
    if [[ -s $out/kustomize.err ]]; then
        echo "k8s: INVALID: the kustomization does not render:"; cat "$out/kustomize.err"; exit 1
    fi
    renderer="validate.py render (no kubectl or kustomize on this machine)"
    cp "$out/fallback.yaml" "$out/rendered.yaml"
fi
echo "k8s: rendered with $renderer: $(grep -c '^kind:' "$out/rendered.yaml") objects"
if [[ $renderer != validate.py* ]]; then
    python3 "$here/validate.py" compare "$out/rendered.yaml" "$out/fallback.yaml"
    echo "k8s: validate.py's own rendering gives the same objects"
fi

status=0
for v in $versions; do
    echo "k8s: kubernetes-validate $(python3 -c 'import importlib.metadata as m; print(m.version("kubernetes-validate"))') --strict, Kubernetes $v:"
    # One file per object so that every object is reported by name.
    python3 - "$out/rendered.yaml" "$out/objects" <<'PY'
import os, sys, yaml
os.makedirs(sys.argv[2], exist_ok=True)
for i, o in enumerate(d for d in yaml.safe_load_all(open(sys.argv[1])) if d):
    with open(os.path.join(sys.argv[2], f"{i:02d}-{o['kind']}-{o['metadata']['name']}.yaml"), "w") as f:
        yaml.safe_dump(o, f)
PY
    kubernetes-validate --strict -k "$v" "$out"/objects/*.yaml | sed "s|$out/objects/|  |" || status=1
done
echo "k8s: cross-object checks:"
python3 "$here/validate.py" check "$out/rendered.yaml" "$root/proto" || status=1
echo "k8s: $( [[ $status -eq 0 ]] && echo valid || echo INVALID ) in $(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t0" "$(date +%s.%N)") s"
exit $status
