#!/usr/bin/env sh
# How static/vendor/three.min.js was made (run by hand when upgrading; the page never loads a CDN):
# three.js from the npm registry, only the classes the dashboard's 3D view uses, bundled and minified
# by esbuild into one ES module; the licence travels beside it.
set -eu
VERSION="${1:-0.187.0}"
HERE="$(cd "$(dirname "$0")" && pwd)"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
cd "$WORK"
npm init -y >/dev/null
npm install --no-audit --no-fund --silent "three@$VERSION" esbuild@0.28.2
cat > entry.js <<'JS'
export {
  BoxGeometry, CanvasTexture, CapsuleGeometry, Color, CylinderGeometry, DirectionalLight, GridHelper, Group,
  HemisphereLight, Matrix4, Mesh, MeshStandardMaterial, PerspectiveCamera, REVISION, SRGBColorSpace, Scene,
  SphereGeometry, Spherical, Vector3, WebGLRenderer,
} from "three";
JS
npx esbuild entry.js --bundle --format=esm --minify --legal-comments=inline --target=es2020 \
  --outfile="$HERE/static/vendor/three.min.js"
cp node_modules/three/LICENSE "$HERE/static/vendor/three.LICENSE"
echo "three.js $VERSION -> $HERE/static/vendor/three.min.js"
