"""
The evidence benchmark (``hcloth_bench`` / ``python -m hcloth_ros.bench``).

Speed against accuracy, stability maps, the paper's figures and the peer simulators.
"""
