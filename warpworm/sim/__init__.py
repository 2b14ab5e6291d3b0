"""The batched simulator: Model / State / Control, the Simulator and its solver layouts."""
