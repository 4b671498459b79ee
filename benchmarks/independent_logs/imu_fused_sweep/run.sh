#!/bin/bash
# run.sh NAME [extra args] -> runs/NAME/, appends to results.txt (uses logs/NAME.args)
cd "$(dirname "$0")"
n=$1; shift
tag=${TAG:-}
rm -rf runs/$n$tag
s=$(date +%s.%N)
timeout 1200 tire-learning estimate logs/$n.csv --vehicle logs/$n.json --out runs/$n$tag --no-progress $( [ -n "$DEF" ] || cat logs/$n.args) "$@" > runs/$n$tag.out 2> runs/$n$tag.err
rc=$?
e=$(date +%s.%N)
python score.py $n $rc $(echo "$e - $s" | bc) "$tag" | tee -a results$tag.txt
