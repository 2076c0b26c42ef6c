# Sourced by the end-to-end scripts: pvpython's stderr goes to the test log, and any error VTK or
# ParaView reported there (a reader that could not parse a file still hands back an empty dataset)
# fails the test.
check_pvpython_errors() {
  cat "$1" >&2
  if grep -qE 'ERR\||ERROR|Traceback' "$1"; then
    echo "FAIL: ParaView reported errors reading the files (see above)"
    exit 1
  fi
}
pvpython_failed() {
  cat "$1" >&2
  echo "FAIL: pvpython exited with an error (see above)"
  exit 1
}
