# parsolve on Debian 12 with Debian's PETSc 3.18 / MUMPS / Open MPI stack.
#   docker build -t parsolve .
#   docker run --rm parsolve                      # the Kirsch demo on 2 ranks
#   docker run --rm -v $PWD:/data parsolve bash scripts/mpirun.sh -n 4 .venv/bin/parsolve run /data/scene.toml -o /data/out.h5
FROM debian:bookworm-slim
ENV DEBIAN_FRONTEND=noninteractive
WORKDIR /opt/parsolve
COPY pyproject.toml README.md ./
COPY parsolve ./parsolve
COPY scripts ./scripts
COPY configs ./configs
COPY tests ./tests
RUN bash scripts/setup.sh && rm -rf /var/lib/apt/lists/*
ENV PATH=/opt/parsolve/.venv/bin:$PATH
CMD ["bash", "scripts/demo.sh"]
