# syntax=docker/dockerfile:1
# The ferrobus image: the one binary and the built-in profiles on a distroless base (glibc and
# nothing else: no shell, no package manager), run as an unprivileged user (nonroot, 65532).
# linux/amd64 and linux/arm64: the build stage runs on the builder's own platform and
# cross-compiles for the other, so no emulation is needed.
#
#   docker build -t ferrobus .
#   docker buildx build --platform linux/amd64,linux/arm64 -t ferrobus .
#   docker run --rm ferrobus demo
#
# Serial devices, the mounted config and compose with mosquitto: docs/container.md.

ARG RUST_VERSION=1.95

FROM --platform=$BUILDPLATFORM docker.io/library/rust:${RUST_VERSION}-slim-bookworm AS build
ARG TARGETARCH
# The SunSpec models are embedded at build time from pysunspec2, the SunSpec Alliance's client.
ARG PYSUNSPEC2_VERSION=1.3.7
WORKDIR /src
RUN set -eu; \
    build_arch="$(dpkg --print-architecture)"; \
    case "$TARGETARCH" in \
        amd64) triple=x86_64-unknown-linux-gnu; gnu=x86-64 ;; \
        arm64) triple=aarch64-unknown-linux-gnu; gnu=aarch64 ;; \
        *) echo "ferrobus images are built for amd64 and arm64, not $TARGETARCH" >&2; exit 1 ;; \
    esac; \
    packages="python3 python3-pip"; \
    if [ "$TARGETARCH" != "$build_arch" ]; then \
        packages="$packages gcc-$gnu-linux-gnu libc6-dev-$TARGETARCH-cross"; \
        rustup target add "$triple"; \
    fi; \
    apt-get update; \
    apt-get install -y --no-install-recommends $packages; \
    rm -rf /var/lib/apt/lists/*; \
    pip3 install --no-cache-dir --break-system-packages "pysunspec2==$PYSUNSPEC2_VERSION"; \
    echo "$triple" > /triple
COPY . .
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target,id=ferrobus-target-$TARGETARCH \
    set -eu; \
    triple="$(cat /triple)"; \
    if [ "$TARGETARCH" != "$(dpkg --print-architecture)" ]; then \
        export "CARGO_TARGET_$(echo "$triple" | tr 'a-z-' 'A-Z_')_LINKER=${triple%%-*}-linux-gnu-gcc"; \
    fi; \
    CARGO_PROFILE_RELEASE_STRIP=symbols cargo build --release --locked -p ferrobus-cli --bin ferrobus --target "$triple"; \
    scripts/image-root.sh --bin "target/$triple/release/ferrobus" --out /rootfs

FROM gcr.io/distroless/cc-debian12:nonroot
COPY --from=build /rootfs/ /
COPY --from=build --chown=nonroot:nonroot /rootfs/var/lib/ferrobus/ /var/lib/ferrobus/
USER nonroot
WORKDIR /var/lib/ferrobus
VOLUME ["/var/lib/ferrobus"]
# 502: the gateway's Modbus/TCP; 9100: the status endpoint (--metrics 0.0.0.0:9100).
EXPOSE 502 9100
ENTRYPOINT ["/usr/bin/ferrobus"]
CMD ["--help"]
