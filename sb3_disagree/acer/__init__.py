from sb3_disagree.acer.acer import ACER
from sb3_disagree.acer.policies import ACERPolicy, CnnPolicy, MlpPolicy

__all__ = ["ACER", "ACERPolicy", "CnnPolicy", "MlpPolicy"]
