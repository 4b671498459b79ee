#!/bin/bash
# run.sh NAME [extra args] -> runs/NAME/, appends to results.txt
cd "$(dirname "$0")"
n=$1; shift
veh=""; [ -f logs/$n.json ] && veh="--vehicle logs/$n.json"
rm -rf runs/$n
s=$(date +%s.%N)
timeout 1200 tire-learning estimate logs/$n.csv $veh --out runs/$n --no-progress "$@" > runs_$n.out 2> runs_$n.err
rc=$?
e=$(date +%s.%N)
python score.py $n $rc $(echo "$e - $s" | bc) | tee -a results.txt
