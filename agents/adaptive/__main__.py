"""``python -m agents.adaptive``: train the in-frame sampler (:func:`agents.adaptive.train.main`)."""

from agents.adaptive.train import main

if __name__ == "__main__":
    raise SystemExit(main())
