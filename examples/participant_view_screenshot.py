"""Screenshot of a study participant's window: what ``hasa-drive study`` shows a participant.

A synthetic participant drives ``studies/paper.toml`` through a virtual G29 in
a real window, in real time, and the window is saved ``--at`` seconds into the
practice run: no ghost markings, no HUD, a bonnet and dashboard, road and
grass bands. Run it on a desktop or under a virtual X server::

    xvfb-run -a -s "-screen 0 1280x720x24" python examples/participant_view_screenshot.py

(``docs/participant_view.png`` was made that way.) The session's recordings go
to a temporary folder and are thrown away.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from hasa_env.devices import InputManager, JoystickCalibration, init_pygame_input
from hasa_env.devices.calibration import shipped_calibration
from hasa_env.devices.virtual import VirtualJoystick
from hasa_env.drivers import SyntheticDriver, population
from hasa_env.session import DriveSession, Study, StudySession, VirtualWheelDriver
from hasa_env.session.scripted import WheelButtonPresser

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, default=ROOT / "studies" / "paper.toml")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "participant_view.png")
    parser.add_argument("--at", type=float, default=6.0, help="s into the practice run")
    args = parser.parse_args()
    if os.environ.get("SDL_VIDEODRIVER", "") == "dummy":
        raise SystemExit("needs a real window: run it on a desktop or under xvfb-run")
    pg = init_pygame_input()
    display = pg.display.set_mode((1280, 720))
    study = Study.load(args.study)
    wheel = VirtualJoystick.g29()
    g29 = shipped_calibration("g29")
    assert isinstance(g29, JoystickCalibration)
    fields = {k: getattr(g29, k) for k in g29.__dataclass_fields__ if k != "device"}
    profile = JoystickCalibration(**{**fields, "match_names": (wheel.name,)})
    inputs = InputManager(profiles=[profile], pygame_module=pg)
    params = {p.name: p for p in population("paper", seed=0)}["Ill"]
    steer = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)
    press = WheelButtonPresser(wheel, after=0.2)
    saved: list[Path] = []

    def hook(session: DriveSession) -> None:
        steer(session)
        press(session)
        info = session.info
        if session.state == "driving" and info is not None and info["time"] >= args.at:
            if not saved:
                pg.image.save(pg.display.get_surface(), str(args.out))
                saved.append(args.out)
                pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_ESCAPE, mod=0))

    answers = {"age_band": "25-34", "licence_years": "10", "simulator_experience": "some"}
    with tempfile.TemporaryDirectory() as folder:
        session = StudySession(
            study, "P01", inputs, output=folder, metadata=answers, display=display, hook=hook,
            log=lambda message: None,
        )  # fmt: skip
        try:
            session.run()
        finally:
            session.close()
            inputs.close()
            wheel.detach()
    print(f"wrote {saved[0]} ({pg.display.get_driver()} window)" if saved else "no screenshot")


if __name__ == "__main__":
    main()
