#!/usr/bin/env python3
"""Monte Carlo of the normal-residual pull on a far arc (docs/error-model.md §5e).

A circle seen from the origin (the one-plane caliper: baseline e = 0.1 m, f = 1000 px), one
point per image column on the visible arc, Gaussian noise along each viewing ray with
sigma_z = z^2/(e f) sigma_v. Fits: 'w' = orthogonal residuals weighted as the solver's
weighted fit (sigma projected on the normal, lateral floor 0.2), 'o' = unweighted orthogonal,
'ray' = residual along the ray (solvers/stem/along.rs). Prints the diameter error (mm):
mean, median, SD over 300 draws. Needs numpy and scipy.
"""
import numpy as np
from scipy.optimize import least_squares
rng=np.random.default_rng(1)
def sim(R,z,sv,e=0.1,f=1000.0):
    c=np.array([0.0,z+R])
    a=np.arccos(R/(z+R))           # half-angle of the visible arc about the centre
    # columns evenly spaced in x/z
    ang=np.linspace(-a,a,2000); P=c+R*np.stack([np.sin(ang),-np.cos(ang)],1)
    u=P[:,0]/P[:,1]*f
    cols=np.arange(np.ceil(u.min()),np.floor(u.max())+1)
    # per column take the point on the front arc with that u
    pts=np.array([P[np.argmin(np.abs(u-k))] for k in cols])
    d=np.linalg.norm(pts,axis=1); g=pts/d[:,None]
    sr=(d**2/(e*f))*sv              # along-ray sigma (m)
    return pts,g,sr,c
def fit(pts,g,sr,mode,rounds=10,floor=0.2):
    # hyper-ish start: algebraic Kasa
    A=np.c_[2*pts,np.ones(len(pts))]; b=(pts**2).sum(1)
    sol=np.linalg.lstsq(A,b,rcond=None)[0]; c=sol[:2]; r=np.sqrt(sol[2]+c@c)
    th=np.r_[c,r]
    for it in range(rounds):
        cc=th[:2]
        dd=pts-cc; n=dd/np.linalg.norm(dd,axis=1)[:,None]
        if mode=='w': s=sr*np.sqrt((n*g).sum(1)**2+floor**2)
        elif mode=='o': s=np.ones(len(pts))*sr.mean()
        fun=lambda t:(np.linalg.norm(pts-t[:2],axis=1)-t[2])/s
        th=least_squares(fun,th).x
    return th[2]
def ray_ml(pts,g,sr,th0):
    # exact: residual along the ray: distance along ray from the point to the circle's front intersection
    def fun(t):
        c=t[:2]; r=t[2]
        # ray from origin with dir g: solve |s g - c| = r, front root
        b=(g@c) if False else g.dot(c) if False else (g*c).sum(1)
        disc=b*b-((c@c)-r*r)
        disc=np.maximum(disc,0)
        s=b-np.sqrt(disc)
        return (np.linalg.norm(pts,axis=1)-s)/sr
    return least_squares(fun,th0).x[2]
for R,z,sv in [(0.0375,2.7,0.15),(0.08,2.7,0.15),(0.14,2.8,0.15),(0.0375,1.5,0.15),(0.3,2.7,0.15)]:
    out={'w':[],'o':[],'ray':[]}
    for t in range(300):
        pts,g,sr,c=sim(R,z,sv)
        noisy=pts+g*(sr*rng.standard_normal(len(pts)))[:,None]
        dn=np.linalg.norm(noisy,axis=1); gn=noisy/dn[:,None]
        for m in ['w','o']:
            try: out[m].append(fit(noisy,gn,sr,m)-R)
            except Exception as ex: pass
        try: out['ray'].append(ray_ml(noisy,gn,sr,np.r_[c,R])-R)
        except Exception: pass
    print(f"R={R} z={z} n={len(pts)} sr={sr.mean()*1000:.1f}mm", {m:(round(np.mean(v)*2000,2),round(np.median(v)*2000,2),round(np.std(v)*2000,2)) for m,v in out.items()})
