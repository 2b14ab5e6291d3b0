from warpworm.cli import run

run()
