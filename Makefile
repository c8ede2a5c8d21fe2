# Two entry points for a fresh Debian 12 machine (run as root, or with sudo available):
#   make all  [ARGS="snakemake options/targets"]   install what is missing, run the workflow
#   make test [PYTEST_ARGS="..."]                   install what is missing, run the tests
# A second run installs nothing: apt packages are checked with dpkg, the venv by a stamp.
SHELL := /bin/bash
VENV := .venv
STAMP := $(VENV)/.installed
# libopenblas0-serial: PETSc's BLAS/LAPACK (Debian's alternatives pick it over the reference BLAS);
# MUMPS's dense fronts are about 3x faster with it (docs/decisions.md, "OpenBLAS and MUMPS")
APT_PACKAGES := python3-dolfinx-real python3-venv python3-h5py openmpi-bin g++ libopenblas0-serial
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
WHEELS := $(wildcard /opt/wheels)
ARGS ?=
CORES := $(if $(findstring --cores,$(ARGS)),,--cores 2)
PYTEST_ARGS ?=

# Open MPI refuses root unless told; CI and the device machines run as root.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMP_NUM_THREADS ?= 1

.PHONY: all test install system lint dry-run benchmark clean-results slurm-system slurm-up slurm-down slurm-status

# A one-node SLURM cluster on localhost (workflow/cluster/local-slurm.sh), for running the
# workflow through profiles/slurm here; its packages are installed only by these targets.
SLURM_PACKAGES := slurmctld slurmd slurm-client slurmdbd munge mariadb-server
SLURM_SCRIPT := workflow/cluster/local-slurm.sh

all: $(STAMP)
	$(VENV)/bin/snakemake $(CORES) $(ARGS)

# The SLURM test's packages too, where this user may install them (root, or sudo without a
# password); elsewhere tests/test_slurm.py is skipped and says why.
CAN_INSTALL := $(shell { [ "$$(id -u)" = 0 ] || sudo -n true 2>/dev/null; } && echo yes)

test: $(STAMP) $(if $(CAN_INSTALL),slurm-system)
	$(VENV)/bin/python -m pytest $(PYTEST_ARGS)

install: $(STAMP)

system:
	@dpkg -s $(APT_PACKAGES) >/dev/null 2>&1 || { \
	  echo "installing Debian packages: $(APT_PACKAGES)"; \
	  $(SUDO) apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q $(APT_PACKAGES); }

$(STAMP): requirements.txt pyproject.toml | system
	test -x $(VENV)/bin/python || /usr/bin/python3 -m venv --system-site-packages $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip
	$(VENV)/bin/pip install -q $(if $(WHEELS),--find-links $(WHEELS)) -r requirements.txt
	$(VENV)/bin/pip install -q --no-deps --no-build-isolation -e .
	$(VENV)/bin/python -c "import numpy, dolfinx, torch; assert numpy.__version__ < '2'; print('numpy', numpy.__version__, 'dolfinx', dolfinx.__version__, 'torch', torch.__version__)"
	touch $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests workflow benchmarks
	$(VENV)/bin/snakemake --lint --cores 1

dry-run: $(STAMP)
	$(VENV)/bin/snakemake -n $(CORES) $(ARGS)

benchmark: $(STAMP)
	$(VENV)/bin/python benchmarks/fem_speed.py

slurm-system:
	@dpkg -s $(SLURM_PACKAGES) >/dev/null 2>&1 || { \
	  echo "installing Debian packages: $(SLURM_PACKAGES)"; \
	  $(SUDO) apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q --no-install-recommends $(SLURM_PACKAGES); }

slurm-up: slurm-system
	$(SUDO) $(SLURM_SCRIPT) up

slurm-down:
	$(SUDO) $(SLURM_SCRIPT) down

slurm-status:
	$(SLURM_SCRIPT) status
