# Sourced, not run: a queue of named shell jobs that N processes take from, for the scripts
# that run many independent long jobs on a 2-core machine (scripts/run_tests.sh,
# scripts/sync_validation.sh). One job at a time leaves a core idle whenever the running job is
# single-threaded for a while; two lanes taking from a queue ordered longest first keep both
# busy, and nothing long starts last.
#
#   source scripts/lanes.sh
#   lane_job NAME COMMAND [ARG...]   # queue one job (NAME: a file name, no spaces)
#   lanes_run LANES DIR PRINT        # run the queue; 1 if any job failed
#
# Each job's output goes to DIR/NAME.log (kept, for callers that search the logs). When a job
# ends, one line says whether it passed and how long it took, printed under a lock so lines
# and logs never interleave; PRINT `log` prints the job's whole log after that line, `failures`
# prints the end of a failed job's log only. The failed jobs' names are in DIR/failed.

lane_queue=()

lane_job() {
  local name=$1
  shift
  lane_queue+=("$name $(printf '%q ' "$@")")
}

# lane_run_one DIR PRINT NAME COMMAND-LINE: one queued job (runs in a fresh bash under xargs).
lane_run_one() {
  local dir=$1 print=$2 name=$3 command=$4 began=$SECONDS status=0
  eval "$command" >"$dir/$name.log" 2>&1 || status=$?
  {
    flock 9
    if [ $status -eq 0 ]; then
      echo "== $(date +%H:%M:%S) $name: passed in $((SECONDS - began)) s"
    else
      echo "== $(date +%H:%M:%S) $name: FAILED (exit $status) in $((SECONDS - began)) s"
      echo "$name" >>"$dir/failed"
    fi
    if [ "$print" = log ]; then
      echo "   $command"
      cat "$dir/$name.log"
    elif [ $status -ne 0 ]; then
      echo "   $command; its log's end:"
      tail -20 "$dir/$name.log" | sed 's/^/    /'
    fi
  } 9>"$dir/lock"
}
export -f lane_run_one

lanes_run() {
  local lanes=$1 dir=$2 print=$3
  [ ${#lane_queue[@]} -gt 0 ] || return 0
  printf '%s\0' "${lane_queue[@]}" |
    xargs -0 -P "$lanes" -I{} bash -c 'lane_run_one "$0" "$1" "${2%% *}" "${2#* }"' \
      "$dir" "$print" {}
  [ ! -s "$dir/failed" ]
}
