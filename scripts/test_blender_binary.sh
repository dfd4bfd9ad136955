#!/usr/bin/env bash
# The extension in a real Blender program (not the bpy module): Debian 13's `blender` package
# (4.3, Python 3.13) in the Debian 13 root of scripts/setup_py313.sh. Installs the built extension
# zip into a fresh user folder, then checks the render engine through Blender's own command line:
#   1. `blender -b shot.blend -a` writes denoised frames where Blender writes its frames, equal
#      to the panel operator's composited frames for the same settings;
#   2. `blender -b shot.blend -s 3 -e 4 -a` (a farm chunk) equals frames 3-4 of the whole run
#      (warm-up frames 2 >= the chunk's distance to the animation's start);
#   3. `blender -b cycles.blend -E AFFINITY_DENOISER -a` renders a Cycles .blend with the engine.
# scripts/test.sh runs it after the bpy suites (the package's first install takes about a minute).
#
# Usage: scripts/test_blender_binary.sh
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
root_run=scripts/in_py313_root.sh
zip=$(ls build-extension/affinity_denoiser-*.zip | head -n 1)
[ -f "$zip" ] || { echo "test_blender_binary: no extension zip (run scripts/build_extension.sh)" >&2; exit 1; }
"$root_run" sh -c 'command -v blender >/dev/null || { apt-get update -qq &&
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends blender >/dev/null; }'

work=build-blender-binary
rm -rf "$work"
mkdir -p "$work/home"
in_root() {  # a command in the root with a user folder of its own
  "$root_run" env HOME="$repo/$work/home" "$@"
}
in_root blender --version | head -n 1
in_root blender --command extension install-file -r user_default --enable "$zip" 2>&1 | tail -n 2

# The scenes: the tests' tiny scene, 4 frames, saved with the engine (shot) and with Cycles.
in_root blender -b --python-exit-code 1 --python-expr "
import sys; sys.path.insert(0, 'tests/blender')
import bpy, scenes
scene = scenes.build_scene(width=32, height=24, frames=4, spp=2)
bpy.ops.wm.read_userpref()  # build_scene read the factory settings: the extension back on
scene.affinity_denoiser.samples_per_frame = 2
scene.affinity_denoiser.warmup_frames = 2
scene.render.filepath = '//cycles_frames/frame_'
bpy.ops.wm.save_as_mainfile(filepath='$repo/$work/cycles.blend')
scene.render.engine = 'AFFINITY_DENOISER'
scene.render.filepath = '//engine/frame_'
bpy.ops.wm.save_as_mainfile(filepath='$repo/$work/shot.blend')
" >"$work/build_scene.log" 2>&1 || { tail -n 30 "$work/build_scene.log"; exit 1; }

start=$(date +%s)
in_root blender -b "$work/shot.blend" -a >"$work/animation.log" 2>&1 || { tail -n 30 "$work/animation.log"; exit 1; }
echo "blender -b shot.blend -a: $(ls "$work/engine" | tr '\n' ' ')($(($(date +%s) - start)) s)"
in_root blender -b "$work/shot.blend" -o "//chunk/frame_" -s 3 -e 4 -a >"$work/chunk.log" 2>&1 \
  || { tail -n 30 "$work/chunk.log"; exit 1; }
echo "blender -b shot.blend -s 3 -e 4 -a: $(ls "$work/chunk" | tr '\n' ' ')"
in_root blender -b "$work/cycles.blend" -E AFFINITY_DENOISER -o "//engine_e/frame_" -a >"$work/engine_e.log" 2>&1 \
  || { tail -n 30 "$work/engine_e.log"; exit 1; }
echo "blender -b cycles.blend -E AFFINITY_DENOISER -a: $(ls "$work/engine_e" | tr '\n' ' ')"
in_root blender -b "$work/cycles.blend" -o "//cycles_frames/frame_" -a >"$work/cycles.log" 2>&1 \
  || { tail -n 30 "$work/cycles.log"; exit 1; }
in_root blender -b "$work/shot.blend" --python-exit-code 1 --python-expr "
import bpy
bpy.context.scene.render.filepath = '//operator/frame_'
assert bpy.ops.affinity_denoiser.render_animation() == {'FINISHED'}
" >"$work/operator.log" 2>&1 || { tail -n 30 "$work/operator.log"; exit 1; }

in_root blender -b --python-exit-code 1 --python-expr "
import sys; sys.path.insert(0, 'tests/blender')
import numpy as np, scenes
work = '$work'
frame = lambda folder, f: scenes.read_image(f'{work}/{folder}/frame_{f:04d}.png')
for f in range(1, 5):
    engine = frame('engine', f)
    operator = scenes.read_image(f'{work}/operator/affinity_denoised/final_{f:04d}.png')
    assert np.array_equal(engine, operator), f'frame {f}: engine and operator differ'
    assert np.array_equal(engine, frame('engine_e', f)), f'frame {f}: -E differs'
    plain = np.abs(frame('cycles_frames', f) - engine).mean()
    assert plain > 0.01, f'frame {f}: the engine frame is plain Cycles ({plain})'
for f in (3, 4):
    assert np.array_equal(frame('chunk', f), frame('engine', f)), f'chunk frame {f} differs'
print('test_blender_binary: 3 checks passed (engine = operator = -E on 4 frames; chunk 3-4 = whole run)')
" 2>&1 | grep -v "^Blender\|^Read\|^$"
