# piezodyn on Debian bookworm (dolfinx 0.5.2 from Debian). See docs/docker.md.
#   docker build -t piezodyn .
#   docker run --rm --user "$(id -u):$(id -g)" -v "$PWD/results:/work/results" piezodyn
FROM debian:bookworm

WORKDIR /opt/piezodyn

# Layer 1, apt packages: depends on the install script only, so a source edit does not reinstall them.
COPY .ci/install.sh .ci/install.sh
RUN PIEZODYN_NO_TEST_EXTRAS=1 bash .ci/install.sh packages && rm -rf /var/lib/apt/lists/*

# Layer 2, the project: the source (see .dockerignore: no host .venv, results or .git), then its venv.
COPY . .
RUN PIEZODYN_NO_LINT=1 bash .ci/install.sh project \
    && chmod -R a+rX /opt/piezodyn \
    && useradd --create-home --uid 1000 --user-group piezodyn \
    && mkdir -p /work && chmod 1777 /work

# Any user (`docker run --user $(id -u)`, even one without a passwd entry) gets a writable HOME and
# caches: the dolfinx/FFCx JIT cache ($XDG_CACHE_HOME/fenics), numba's cache and matplotlib's config
# live under /tmp instead of the read-only install tree or a home directory that does not exist.
ENV PATH=/opt/piezodyn/.venv/bin:$PATH \
    HOME=/tmp \
    XDG_CACHE_HOME=/tmp/.cache \
    NUMBA_CACHE_DIR=/tmp/.cache/numba \
    MPLCONFIGDIR=/tmp/.cache/matplotlib \
    MPLBACKEND=Agg \
    PYTHONDONTWRITEBYTECODE=1 \
    OMPI_MCA_rmaps_base_oversubscribe=1 \
    OMPI_MCA_btl_vader_single_copy_mechanism=none \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# Non-root by default; results go under /work (mount a host directory on /work/results).
USER piezodyn
WORKDIR /work
ENTRYPOINT ["piezodyn"]
CMD ["run", "/opt/piezodyn/cases/usdc-transducer.toml", "--out", "/work/results/usdc-transducer"]
