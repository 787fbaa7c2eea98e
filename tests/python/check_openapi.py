"""Checks recorded exchanges with the daemon against its OpenAPI document.

Usage: check_openapi.py DOC.json EXCHANGES.json

EXCHANGES.json is a list of {"method", "route" (the path template), "path",
"status", "content_type", "body" (text)} that tests/e2e/daemon_web.rs made
against a running daemon. For each one: the route and method must be in
the document, the status among the operation's documented answers, the
content type the documented one, and a JSON body valid against the
documented schema (Draft 2020-12, the dialect of OpenAPI 3.1); a
server-sent event stream's every event data against the `TestStatus`
schema. Every operation of the document must have been exercised.
Prints one line per problem and a summary; exits 1 on any problem.
"""

import json
import sys

from jsonschema import Draft202012Validator


def validator(doc, schema):
    root = dict(schema)
    root["components"] = doc.get("components", {})
    return Draft202012Validator(root)


def sse_data(text):
    for block in text.replace("\r\n", "\n").split("\n\n"):
        data = [line[5:].lstrip(" ") for line in block.split("\n") if line.startswith("data:")]
        if data:
            yield "\n".join(data)


def check(doc, ex):
    problems = []
    where = f'{ex["method"]} {ex["path"]} ({ex["route"]}) → {ex["status"]}'
    op = doc["paths"].get(ex["route"], {}).get(ex["method"].lower())
    if op is None:
        return [f"{where}: the route is not in the document"]
    answer = op["responses"].get(str(ex["status"]))
    if answer is None:
        return [f"{where}: status not documented (documented: {sorted(op['responses'])})"]
    content = answer.get("content", {})
    if not content:
        return problems
    got = (ex["content_type"] or "").split(";")[0].strip()
    if got not in content:
        return [f"{where}: content type {got!r}, documented {sorted(content)}"]
    schema = content[got].get("schema")
    body = ex["body"]
    if got == "application/json" and schema is not None:
        try:
            value = json.loads(body)
        except ValueError as e:
            return [f"{where}: not JSON: {e}"]
        for err in validator(doc, schema).iter_errors(value):
            problems.append(f"{where}: {'/'.join(map(str, err.absolute_path))}: {err.message}")
    elif got == "text/event-stream":
        status = validator(doc, {"$ref": "#/components/schemas/TestStatus"})
        events = list(sse_data(body))
        if not events:
            problems.append(f"{where}: no events")
        for data in events:
            for err in status.iter_errors(json.loads(data)):
                problems.append(f"{where}: event {'/'.join(map(str, err.absolute_path))}: {err.message}")
    return problems


def main():
    doc = json.load(open(sys.argv[1]))
    exchanges = json.load(open(sys.argv[2]))
    problems = []
    for ex in exchanges:
        problems += check(doc, ex)
    done = {(ex["route"], ex["method"].lower()) for ex in exchanges}
    for route, item in doc["paths"].items():
        for method in item:
            if (route, method) not in done:
                problems.append(f"{method.upper()} {route}: documented but not exercised")
    for p in problems:
        print(p)
    operations = sum(len(item) for item in doc["paths"].values())
    print(f"{len(exchanges)} exchanges over {operations} documented operations: {len(problems)} problems")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
