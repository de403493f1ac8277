"""``rangekit check``: the steps that look before scanning, what they measure, and the job that runs them."""
