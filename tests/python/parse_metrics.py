"""Parses the daemon's /metrics text with the Prometheus client library's
OpenMetrics parser (strict: a malformed exposition raises) and prints its
samples as JSON: [{"family", "type", "name", "labels", "value"}, ...].

Usage: parse_metrics.py METRICS.txt
"""

import json
import sys

from prometheus_client.openmetrics.parser import text_string_to_metric_families


def main():
    text = open(sys.argv[1], encoding="utf-8").read()
    samples = []
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            samples.append({
                "family": family.name,
                "type": family.type,
                "name": s.name,
                "labels": s.labels,
                "value": s.value,
            })
    json.dump(samples, sys.stdout)


if __name__ == "__main__":
    main()
