# flexmm — set-up, demo, tests, benchmarks and batch reproduction.
# `make demo` and `make test` install everything they need into .venv on a fresh machine.

PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed-stamp
# two workers on two cores: the suite is CPU-bound (numba compiles, integrations), one process per core
PYTEST_ARGS ?= -n auto --dist worksteal

# `make reproduce`: every scene in configs/ and every sweep in sweeps/ as a file target, so
# `make -j2 reproduce` runs two at a time and an interrupted `make` resumes where it stopped
# (a dataset appears only when its run finished; a sweep skips its finished points).
CONFIGS   := $(wildcard configs/*.yaml)
SWEEPS    := $(wildcard sweeps/*.yaml)
RUN_OUT   := $(patsubst configs/%.yaml,runs/%/dataset.nc,$(CONFIGS))
SWEEP_OUT := $(patsubst sweeps/%.yaml,runs/sweeps/%/sweep.nc,$(SWEEPS))
FIGURES   := $(patsubst sweeps/%.yaml,runs/figures/%.png,$(SWEEPS))
# `make gallery`: one short movie per scene (GALLERY_EXT=mp4 for MP4s, through the mp4 extra's ffmpeg)
GALLERY_EXT ?= gif
GALLERY   := $(patsubst configs/%.yaml,runs/gallery/%.$(GALLERY_EXT),$(CONFIGS))
# `make docs`: the documentation site in runs/site (mkdocs.yml); the gallery's entries, one per scene,
# are file targets (remade when the scene changes; `make -j2 docs` makes two at a time)
DOCS_STAMP  = $(VENV)/.docs-stamp
RELEASE_STAMP = $(VENV)/.release-stamp
DOCS_GALLERY := $(patsubst configs/%.yaml,runs/docs/gallery/%.json,$(CONFIGS))
SITE_DIR ?= runs/site
# worker processes per sweep: one per core, or one when make itself runs jobs in parallel (-jN)
SWEEP_WORKERS ?= $(if $(filter -j%,$(MAKEFLAGS)),1,0)

.DELETE_ON_ERROR:
.PHONY: install precompile demo test test-slow bench clean reproduce figures gallery docs release-check

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,dask,mp4]'
	touch $@

install: $(STAMP)

# `make precompile`: compile the kernels of every scene in configs/ now, so that no first run waits
# for them (`flexmm plan` runs a scene's accuracy pilots, which compile what its run uses)
precompile: $(STAMP)
	@for c in $(CONFIGS); do echo "compiling $$c"; $(BIN)/flexmm plan $$c > /dev/null || exit 1; done

demo: $(STAMP)
	$(BIN)/flexmm run configs/lego_vector_soliton.yaml

# the suite builds the documentation site (quick in the default suite, in full as a slow test)
test: $(STAMP) $(DOCS_STAMP)
	$(BIN)/python -m pytest $(PYTEST_ARGS)

test-slow: $(STAMP) $(DOCS_STAMP)
	$(BIN)/python -m pytest -m slow $(PYTEST_ARGS)

reproduce: $(RUN_OUT) $(SWEEP_OUT)

runs/%/dataset.nc: configs/%.yaml | $(STAMP)
	$(BIN)/flexmm run $< --out runs/$* --quiet

runs/sweeps/%/sweep.nc: sweeps/%.yaml $(CONFIGS) | $(STAMP)
	$(BIN)/flexmm sweep $< --out runs/sweeps/$* --workers $(SWEEP_WORKERS)

figures: $(FIGURES)

runs/figures/%.png: runs/sweeps/%/sweep.nc
	$(BIN)/python -m flexmm.sweep.plot runs/sweeps/$* $@

gallery: $(GALLERY)

runs/gallery/%.$(GALLERY_EXT): runs/%/dataset.nc
	$(BIN)/flexmm render runs/$* --out $@ --max-frames 120 --width 720 --spacetime --quiet

$(DOCS_STAMP): pyproject.toml | $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	touch $@

runs/docs/gallery/%.json: configs/%.yaml | $(DOCS_STAMP)
	$(BIN)/python docs/hooks/gallery.py $< runs/docs/gallery

docs: $(DOCS_GALLERY) | $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir $(SITE_DIR)

# `make release-check`: build the sdist and the wheel into dist/ and check their metadata (twine)
$(RELEASE_STAMP): pyproject.toml | $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[release]'
	touch $@

release-check: | $(RELEASE_STAMP)
	rm -rf dist
	$(BIN)/python -m build --outdir dist .
	$(BIN)/twine check --strict dist/*

bench: $(STAMP)
	@if [ -f benchmarks/run.py ]; then $(BIN)/python benchmarks/run.py; \
	else echo "bench: benchmarks/run.py does not exist yet"; fi

clean:
	rm -rf runs/*/ benchmarks/results dist
