# bgc: the README's two commands are `make run` and `make test`.
PYTHON ?= python3
MAIN_MODEL ?= models/dc_motor.yaml

.PHONY: install run test test-all generated clean

install:
	$(PYTHON) -m pip install -q -e ".[test]"

# The main job: compile and simulate the flagship example, write CSV + PNG to results/.
run: install
	bgc simulate $(MAIN_MODEL) --out results/main.csv --plot results/main.png

# Fast suite (slow SARIB runs are marked `slow` and left to test-all).
test:
	$(PYTHON) -m pytest -q -n 2

test-all:
	$(PYTHON) -m pytest -q -n 2 -m ""

# Regenerate the committed modules in generated/ (a test checks they are fresh).
generated:
	for m in models/*.yaml; do bgc compile $$m -o generated || exit 1; done

clean:
	rm -rf results .pytest_cache generated/__pycache__
