FROM debian:bookworm
WORKDIR /opt/piezodyn
COPY . .
RUN bash .ci/install.sh && rm -rf /var/lib/apt/lists/*
ENV PATH=/opt/piezodyn/.venv/bin:$PATH \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 MPLBACKEND=Agg
ENTRYPOINT ["piezodyn"]
CMD ["run", "cases/usdc-transducer.toml", "--out", "results/usdc-transducer"]
