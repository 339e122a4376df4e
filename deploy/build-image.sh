#!/usr/bin/env bash
# Builds Glint's container image without pulling anything: the release binary, the shared
# libraries it links and a minimal /etc go into a build context, then
# `docker build -f deploy/Dockerfile` (FROM scratch) tags glint:VERSION and glint:latest.
#
#   bash deploy/build-image.sh            # cargo build --release --locked -p glint-cli, then the image
#   GLINT_IMAGE_NO_CARGO=1 bash deploy/build-image.sh   # reuse target/release/glint as it is
#   GLINT_IMAGE_PROFILE=debug ...         # the dev profile's binary (cargo build --locked -p glint-cli),
#                                         # e.g. in CI right after the tests built it: no release build
#   GLINT_IMAGE_STRIP=0 ...               # keep the binary's line tables (default: stripped in the image)
#
# Prints the image's tags, its size and the time each part took; then checks that
# `docker run --rm glint:latest --help` works.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
t_start=$(date +%s.%N)

elapsed() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$(date +%s.%N)"; }

if ! docker version --format '{{.Server.Version}}' >/dev/null 2>&1; then
    echo "build-image: no Docker engine answers (docker version failed)" >&2
    exit 1
fi

# 1. The release binary.
profile=${GLINT_IMAGE_PROFILE:-release}
case $profile in
    release) cargo_args=(build --release --locked -p glint-cli) ;;
    debug) cargo_args=(build --locked -p glint-cli) ;;
    *) echo "build-image: GLINT_IMAGE_PROFILE is release or debug, not $profile" >&2; exit 1 ;;
esac
binary=$root/target/$profile/glint
if [[ "${GLINT_IMAGE_NO_CARGO:-0}" == 1 ]]; then
    [[ -x $binary ]] || { echo "build-image: GLINT_IMAGE_NO_CARGO=1 but $binary is missing" >&2; exit 1; }
    echo "build-image: reusing $binary (GLINT_IMAGE_NO_CARGO=1)"
    cargo_s=0
else
    # One cargo build at a time on this machine: wait for any other to finish.
    while pgrep -x cargo >/dev/null; do
        echo "build-image: another cargo is running ($(pgrep -x cargo | tr '\n' ' ')); waiting 60 s"
        sleep 60
    done
    t0=$(date +%s.%N)
    cargo "${cargo_args[@]}"
    cargo_s=$(elapsed "$t0")
    echo "build-image: cargo ${cargo_args[*]} took ${cargo_s} s"
fi

# 2. The build context: rootfs/ is copied to / as it is.
t0=$(date +%s.%N)
ctx=$(mktemp -d "${TMPDIR:-/tmp}/glint-image.XXXXXX")
trap 'rm -rf "$ctx"' EXIT
rootfs=$ctx/rootfs
mkdir -p "$rootfs/usr/local/bin" "$rootfs/etc" "$rootfs/tmp" "$ctx/state"
chmod 1777 "$rootfs/tmp"
cp "$binary" "$rootfs/usr/local/bin/glint"
if [[ "${GLINT_IMAGE_STRIP:-1}" == 1 ]] && command -v strip >/dev/null; then
    # The release profile keeps line tables for backtraces; the image keeps the symbols only.
    strip --strip-debug "$rootfs/usr/local/bin/glint"
fi

# Every shared library the binary links, at the path the loader looks for it (symlinks
# resolved), and the loader itself (ldd prints it as an absolute path without "=>").
libs=$(ldd "$binary" | awk '$2 == "=>" && $3 ~ /^\// { print $3 } $1 ~ /^\// { print $1 }' | sort -u)
if ldd "$binary" | grep -q 'not found'; then
    echo "build-image: ldd cannot resolve every library of $binary:" >&2
    ldd "$binary" >&2
    exit 1
fi
for lib in $libs; do
    mkdir -p "$rootfs$(dirname "$lib")"
    cp -L "$lib" "$rootfs$lib"
done
interp=$(readelf -l "$binary" 2>/dev/null | sed -n 's/.*Requesting program interpreter: \(.*\)]/\1/p' || true)
if [[ -n $interp && ! -e $rootfs$interp ]]; then
    mkdir -p "$rootfs$(dirname "$interp")"
    cp -L "$interp" "$rootfs$interp"
fi

cat >"$rootfs/etc/passwd" <<'EOF'
root:x:0:0:root:/root:/sbin/nologin
glint:x:65532:65532:glint:/state:/sbin/nologin
EOF
cat >"$rootfs/etc/group" <<'EOF'
root:x:0:
glint:x:65532:
EOF
# glibc resolves through /etc/hosts and then DNS (Docker's and Kubernetes' resolvers are
# mounted at /etc/resolv.conf); with glibc >= 2.34 both modules are inside libc.
cat >"$rootfs/etc/nsswitch.conf" <<'EOF'
passwd: files
group:  files
hosts:  files dns
EOF
cp "$root/deploy/Dockerfile" "$ctx/Dockerfile"
stage_s=$(elapsed "$t0")

echo "build-image: context $(du -sh "$ctx" | cut -f1): glint $(du -h "$rootfs/usr/local/bin/glint" | cut -f1) and $(echo "$libs" | wc -w) shared libraries:"
echo "$libs" | sed 's/^/  /'

# 3. The image.
version=$(sed -n '/^\[workspace.package\]/,/^\[/ s/^version *= *"\(.*\)"/\1/p' Cargo.toml | head -1)
hash=$(git rev-parse --short HEAD 2>/dev/null || true)
if [[ -n $hash ]] && ! git diff --quiet HEAD -- 2>/dev/null; then
    hash=$hash-dirty
fi
tag=${version:-0.0.0}${hash:+-$hash}
[[ $profile == release ]] || tag=$tag-$profile
t0=$(date +%s.%N)
# No base image to pull (FROM scratch): the legacy builder and BuildKit both work offline.
docker build --quiet --build-arg VERSION="$tag" -t "glint:$tag" -t glint:latest -f "$ctx/Dockerfile" "$ctx" >/dev/null
docker_s=$(elapsed "$t0")

size=$(docker image inspect glint:latest --format '{{.Size}}')
echo "build-image: glint:$tag and glint:latest, $(python3 -c "import sys; print(f'{int(sys.argv[1]) / 1e6:.1f} MB')" "$size") ($size bytes)"
echo "build-image: times: cargo ${cargo_s} s, context ${stage_s} s, docker build ${docker_s} s, total $(elapsed "$t_start") s"

# 4. It runs: the CLI's help from the image, as the non-root user.
docker run --rm glint:latest --help >/dev/null
echo "build-image: docker run --rm glint:latest --help: ok (user $(docker image inspect glint:latest --format '{{.Config.User}}'))"
