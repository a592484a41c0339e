"""Global performance indices of the case studies (Monte-Carlo workspace integrals)."""
