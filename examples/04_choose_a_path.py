"""Choose a path by simulation

Plan a few candidate paths, screen them under the scene's uncertainty model (start pose,
friction, motors, body mass), certify the chosen one on fresh rollouts, and print the ranking
(P(success) with its interval and the energy of the successful rollouts) and the guarantee
reached. A small choice here (16 rollouts: not enough to certify, so it says what it reached);
`roachplan choose` takes the same settings on the command line.
"""

import roachplan


def main() -> None:
    world = roachplan.load("double_bridge")
    choice = roachplan.choose(world, candidates=2, rollouts=16, budget_s=None, seed=0, workers=2)
    print(f"stopped: {choice.stopped}; {choice.rollouts} rollouts in {choice.wall_time:.1f} s")
    for row in choice.ranking:  # best first
        print(
            f"candidate {row['candidate']} ({row['route']}): P(success) {row['p_success']:.2f} "
            f"[{row['p_low']:.2f}, {row['p_high']:.2f}], relative energy "
            f"{row['relative_energy']:.2f}, {row['rollouts']} rollouts {row['out']}"
        )
    print("chosen candidate:", choice.chosen)
    if choice.guarantee is not None and choice.chosen is not None:
        print("guarantee:", choice.guarantee.sentence(choice.chosen))


if __name__ == "__main__":
    main()
