#!/usr/bin/env bash
# Start a throwaway PostgreSQL server for the history tests and print its URL (for GLASSDIST_TEST_PG_URL).
#
#   url=$(bash scripts/test_postgres.sh start DIR)   # DIR: a new, empty folder; the server listens on a
#   bash scripts/test_postgres.sh stop DIR           # Unix socket in DIR only (no TCP port at all)
#   bash scripts/test_postgres.sh resume DIR         # start the stopped server of DIR again (same data)
#
# The role 'glassdist' (superuser, trust authentication on the socket) can create the tests'
# databases. Run as root, the server runs as the 'postgres' system user. Needs PostgreSQL's
# server programs (Debian/Ubuntu: apt-get install postgresql); exits 1 without them.
set -euo pipefail
cmd=${1:?usage: test_postgres.sh start|stop|resume DIR}
dir=$(realpath -m "${2:?usage: test_postgres.sh start|stop|resume DIR}")
bindir=$(pg_config --bindir 2>/dev/null || true)
if [ -z "$bindir" ] || [ ! -x "$bindir/initdb" ]; then
  bindir=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true)
fi
[ -n "$bindir" ] && [ -x "$bindir/initdb" ] || { echo "PostgreSQL server programs not found" >&2; exit 1; }
as_owner() { if [ "$(id -u)" = 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi; }
case "$cmd" in
  start|resume)
    if [ "$cmd" = start ]; then
      mkdir -p "$dir"
      if [ "$(id -u)" = 0 ]; then chown postgres "$dir"; fi
      as_owner "$bindir/initdb" -D "$dir/data" -U glassdist --auth=trust -E UTF8 >"$dir/initdb.log" 2>&1
    fi
    as_owner "$bindir/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 60 \
      -o "-c listen_addresses='' -c unix_socket_directories='$dir' -c fsync=off" start >/dev/null
    echo "postgresql+psycopg://glassdist@/postgres?host=$dir"
    ;;
  stop)
    as_owner "$bindir/pg_ctl" -D "$dir/data" -m fast -w stop >/dev/null
    ;;
  *) echo "usage: test_postgres.sh start|stop|resume DIR" >&2; exit 2 ;;
esac
