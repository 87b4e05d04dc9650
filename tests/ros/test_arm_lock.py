"""One goal at a time on the arm (`rad_ros.arm_lock`), across threads."""

import threading

from rad_ros.arm_lock import ArmLock


def test_the_arm_goes_to_one_goal_and_back_only_from_it():
    t = [10.0]
    lock = ArmLock(clock=lambda: t[0])
    assert lock.take('/execute_assembly', 'aa') == '' and lock.holder == '/execute_assembly goal aa'
    t[0] = 13.25
    busy = lock.take('/take_apart', 'bb')
    assert busy.startswith('the arm is busy: /execute_assembly goal aa has driven it for 3.2 s'), busy
    lock.give('bb')                               # not its to give
    assert lock.holder == '/execute_assembly goal aa'
    lock.give('aa')
    assert lock.holder == '' and lock.take('/take_apart', 'bb') == ''


def test_of_many_goals_starting_together_exactly_one_drives_the_arm():
    lock, start, won = ArmLock(), threading.Barrier(16), []

    def goal(n):
        start.wait()
        if not lock.take('/execute_assembly', str(n)):
            won.append(n)
    threads = [threading.Thread(target=goal, args=(n,)) for n in range(16)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(won) == 1
