from engine import run
from games.hall_of_mirrors.level import HallOfMirrors

run(HallOfMirrors())
