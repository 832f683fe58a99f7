#!/usr/bin/env bash
# Creates, on a Docker engine without access to a registry, the two base images the Dockerfile's
# FROM lines name, from Debian's own packages, so `docker build .` runs unchanged:
#   debian:bookworm-slim  debootstrap --variant=minbase, trimmed like Debian's slim image
#                         (no docs, man pages or locales; apt lists emptied), then `docker import`;
#   rust:1-bookworm       the same Debian plus what `cargo build` needs to link (gcc, libc6-dev,
#                         ca-certificates for crates.io, pkg-config), with this machine's stable
#                         Rust toolchain copied in at the paths the official image uses
#                         (CARGO_HOME=/usr/local/cargo, RUSTUP_HOME=/usr/local/rustup), and
#                         this machine's CA bundle (crates.io is reached through its trust).
#   redis:7, haproxy:2.6  for deploy/compose.yaml: that Debian with Debian's redis-server or
#                         haproxy, laid out like the official images (redis in /data,
#                         HAProxy's configuration in /usr/local/etc/haproxy/haproxy.cfg).
# An image that already exists is kept (pass --force to rebuild both): CI reuses them between runs.
# Downloaded packages are cached in ${IRS_BASE_CACHE:-~/.cache/irs-planner/debootstrap}.
#   scripts/base-images.sh [--force]
set -euo pipefail
suite=bookworm
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
cache=${IRS_BASE_CACHE:-$HOME/.cache/irs-planner/debootstrap}
force=${1:-}

have() { [ "$force" != --force ] && docker image inspect "$1" >/dev/null 2>&1; }
if have debian:bookworm-slim && have rust:1-bookworm && have redis:7 && have haproxy:2.6; then
  echo "base images exist: debian:bookworm-slim, rust:1-bookworm, redis:7, haproxy:2.6"
  exit 0
fi
command -v debootstrap >/dev/null || {
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
}
mkdir -p "$cache"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Makes a Debian root file system in $1 with the extra packages $2 (comma-separated).
bootstrap() {
  local root=$1 include=$2
  debootstrap --variant=minbase --cache-dir="$cache" ${include:+--include="$include"} \
    "$suite" "$root" "$mirror" >"$work/debootstrap.log" 2>&1 || {
    tail -n 30 "$work/debootstrap.log"
    return 1
  }
  # What Debian's slim images leave out (their dpkg path-exclude list): documentation, manual
  # pages and translations; the package lists are fetched again by `apt-get update`.
  rm -rf "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/* \
    "$root"/usr/share/locale/* "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/*.bin \
    "$root"/var/cache/apt/archives/*.deb "$root"/var/log/*.log
  cat >"$root/etc/dpkg/dpkg.cfg.d/docker-slim" <<'CFG'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
CFG
  echo 'APT::Install-Recommends "false";' >"$root/etc/apt/apt.conf.d/docker-no-recommends"
}

if ! have debian:bookworm-slim; then
  echo "debian:bookworm-slim: debootstrap $suite (minbase)"
  bootstrap "$work/slim" ""
  tar -C "$work/slim" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["bash"]' - debian:bookworm-slim >/dev/null
  rm -rf "$work/slim"
fi

if ! have rust:1-bookworm; then
  toolchain=$(rustc --print sysroot)
  echo "rust:1-bookworm: debootstrap $suite + gcc, and $(rustc --version) from $toolchain"
  bootstrap "$work/rust" "gcc,libc6-dev,ca-certificates,pkg-config,make"
  # The build stage downloads crates over TLS: it trusts what this machine trusts (which may
  # include a TLS-inspecting proxy's authority that Debian's bundle lacks).
  if [ -s /etc/ssl/certs/ca-certificates.crt ]; then
    cp /etc/ssl/certs/ca-certificates.crt "$work/rust/etc/ssl/certs/ca-certificates.crt"
  fi
  mkdir -p "$work/rust/usr/local/rustup/toolchains/stable" "$work/rust/usr/local/cargo/bin"
  # The compiler, the standard library and cargo; not the 800 MB of HTML documentation.
  (cd "$toolchain" && tar -c --exclude=./share/doc . ) |
    tar -C "$work/rust/usr/local/rustup/toolchains/stable" -x
  for tool in cargo rustc rustdoc cargo-clippy clippy-driver rustfmt cargo-fmt; do
    [ -e "$toolchain/bin/$tool" ] && ln -s "../../rustup/toolchains/stable/bin/$tool" \
      "$work/rust/usr/local/cargo/bin/$tool"
  done
  tar -C "$work/rust" -c . | docker import \
    --change 'ENV RUSTUP_HOME=/usr/local/rustup' \
    --change 'ENV CARGO_HOME=/usr/local/cargo' \
    --change 'ENV PATH=/usr/local/cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["bash"]' - rust:1-bookworm >/dev/null
fi
# The compose file's services, from Debian's packages on the slim image (as non-root users).
if ! have redis:7; then
  echo "redis:7: Debian's redis-server on debian:bookworm-slim"
  docker build -q -t redis:7 - >/dev/null <<'DOCKERFILE'
FROM debian:bookworm-slim
RUN apt-get update && apt-get install -y --no-install-recommends redis-server redis-tools \
 && rm -rf /var/lib/apt/lists/* && mkdir -p /data && chown redis:redis /data
WORKDIR /data
USER redis
EXPOSE 6379
CMD ["redis-server", "--dir", "/data", "--protected-mode", "no"]
DOCKERFILE
fi
if ! have haproxy:2.6; then
  echo "haproxy:2.6: Debian's haproxy on debian:bookworm-slim"
  docker build -q -t haproxy:2.6 - >/dev/null <<'DOCKERFILE'
FROM debian:bookworm-slim
RUN apt-get update && apt-get install -y --no-install-recommends haproxy \
 && rm -rf /var/lib/apt/lists/* && mkdir -p /usr/local/etc/haproxy
USER haproxy
STOPSIGNAL SIGUSR1
CMD ["haproxy", "-W", "-db", "-f", "/usr/local/etc/haproxy/haproxy.cfg"]
DOCKERFILE
fi
docker image ls --format '{{.Repository}}:{{.Tag}}  {{.Size}}' | grep -E '^(debian:bookworm-slim|rust:1-bookworm|redis:7|haproxy:2.6) '
