# knit — developer entry points. `make setup && make demo` on a fresh machine, `make test` for the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out/demo

.PHONY: setup demo test test-slow bench presets clean

setup: $(BIN)/knitbake

$(BIN)/knitbake: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@

# List the presets, generate two yarns' fibers with preview images, inspect and validate them, path-trace the
# example straight yarn under the built-in sky, bake a draft asset pack, simulate a diamond-pattern patch stretched
# and released over 9 frames and render frame 4, the full 1.4x stretch, with the strip renderer (demo_patch.png), then
# all 9 frames with one renderer (frames/demo_NN.png and demo_patch.gif).
demo: setup
	@mkdir -p $(OUT)
	$(BIN)/knitbake yarn list
	$(BIN)/knitbake fibers cotton1 --periods 2 -o $(OUT)/cotton1_fibers.bcc --preview $(OUT)/cotton1_preview.png
	$(BIN)/knitbake fibers rayon1 --periods 2 -o $(OUT)/rayon1_fibers.h5 --preview $(OUT)/rayon1_preview.png
	$(BIN)/knitbake inspect $(OUT)/rayon1_fibers.h5
	$(BIN)/knitbake validate $(OUT)/cotton1_fibers.bcc
	$(BIN)/knitbake reference examples/scenes/straight_yarn_sky.toml -o $(OUT)/straight_yarn_sky.exr --spp 16
	$(BIN)/knitbake bake cotton1 --quality draft -o $(OUT)/cotton1_draft.h5
	$(BIN)/knitbake inspect $(OUT)/cotton1_draft.h5
	$(BIN)/knitrun pattern diamond --rows 12 --cols 12 -o $(OUT)/diamond.h5
	$(BIN)/knitrun simulate $(OUT)/diamond.h5 --deform stretch-x=1.4 --frames 9 -o $(OUT)/diamond_yarns.h5
	@printf '%s\n' 'format = "knit-scene"' 'version = "1.0"' 'name = "demo: stretched diamond patch"' \
	  'units = "cm"' 'background = [0.02, 0.02, 0.03]' '[[yarns]]' 'curves = "diamond_yarns.h5"' 'yarn = "cotton1"' \
	  'pack = "cotton1_draft.h5"' 'color = [0.85, 0.3, 0.25]' '[camera]' 'position = [1.5, -0.6, 5.0]' \
	  'look_at = [1.5, 1.2, 0.0]' 'fov_deg = 38.0' 'width = 960' 'height = 720' '[[lights]]' 'type = "directional"' \
	  'direction = [0.5, 0.4, 1.0]' 'irradiance = [2.5, 2.5, 2.5]' '[[lights]]' 'type = "environment"' \
	  'builtin = "sky"' 'scale = [0.3, 0.3, 0.3]' '[render]' 'frame = 4' 'msaa = 4' > $(OUT)/demo_patch.toml
	$(BIN)/knitrun render $(OUT)/demo_patch.toml -o $(OUT)/demo_patch.png --exr $(OUT)/demo_patch.exr
	@mkdir -p $(OUT)/frames
	$(BIN)/knitrun render $(OUT)/demo_patch.toml --frames 0:9 -o $(OUT)/frames/demo_##.png --gif $(OUT)/demo_patch.gif
	@echo "demo outputs in $(OUT)/ (open demo_patch.png, demo_patch.gif and the *_preview.png images)"

test: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

test-slow: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder -m slow

bench: setup
	$(BIN)/python benchmarks/bench_fibers.py
	$(BIN)/python benchmarks/bench_ray_scene.py --preset cotton1
	$(BIN)/python benchmarks/bench_ray_scene.py --preset rayon1
	$(BIN)/python benchmarks/bench_reference.py
	$(BIN)/python benchmarks/bench_knots.py
	$(BIN)/python benchmarks/bench_bake.py
	$(BIN)/python benchmarks/bench_strip_raster.py
	@mkdir -p out/bench
	$(BIN)/knitbake bake cotton1 --quality draft -o out/bench/cotton1_draft.h5
	$(BIN)/knitbake bake cotton1 --quality standard -o out/bench/cotton1_standard.h5
	$(BIN)/knitbake bake cotton1 --quality final -o out/bench/cotton1_final.h5
	$(BIN)/python benchmarks/bench_render.py --pack out/bench/cotton1_standard.h5
	$(BIN)/python benchmarks/bench_floors.py --spp 4,16,64 --out out/bench/refs
	$(BIN)/python benchmarks/bench_compare.py --pack out/bench/cotton1_standard.h5 --reference-dir out/bench/refs \
	  --out out/compare
	$(BIN)/python benchmarks/bench_tradeoff.py --reference-dir out/bench/refs --work-dir out/bench/tradeoff \
	  --packs draft=out/bench/cotton1_draft.h5,standard=out/bench/cotton1_standard.h5,final=out/bench/cotton1_final.h5

# Regenerate data_formats/presets/ from ../shared/reference (the measured tables).
presets: setup
	$(BIN)/python scripts/make_presets.py

clean:
	rm -rf out .pytest_cache build *.egg-info
