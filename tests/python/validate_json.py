"""Validates JSON instances against a JSON Schema with the `jsonschema` package, an independent
validator for the Rust tests (services/tests/integration/common/mod.rs).

stdin: {"schema": <schema>, "instances": [<instance>, ...]}
stdout: one list per instance of its errors, each "<message> at <JSON pointer>".
"""
import json
import sys

import jsonschema


def pointer(path):
    return "".join("/" + str(p).replace("~", "~0").replace("/", "~1") for p in path)


def main():
    job = json.load(sys.stdin)
    validator_class = jsonschema.validators.validator_for(job["schema"])
    validator_class.check_schema(job["schema"])
    validator = validator_class(job["schema"])
    out = [
        [f"{e.message} at {pointer(e.absolute_path)}" for e in validator.iter_errors(instance)]
        for instance in job["instances"]
    ]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
