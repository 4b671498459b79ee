#!/bin/bash
cd "$(dirname "$0")"
for f in logs/*.csv; do
  n=$(basename $f .csv)
  case $n in khz300|imukhz300) continue;; esac
  veh=""; [ -f logs/$n.json ] && veh="--vehicle logs/$n.json"
  rm -rf runs/$n
  s=$(date +%s.%N)
  timeout 600 tire-learning estimate logs/$n.csv $veh --out runs/$n --no-progress > runs_$n.out 2> runs_$n.err
  rc=$?
  e=$(date +%s.%N)
  python score.py $n $rc $(echo "$e - $s" | bc) >> results.txt
done
echo DONE >> results.txt
