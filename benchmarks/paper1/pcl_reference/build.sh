#!/bin/sh
# Build the PCL reference program (Debian: apt-get install -y libpcl-dev cmake g++).
set -e
cd "$(dirname "$0")"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
nice -n 10 cmake --build build -j 1
