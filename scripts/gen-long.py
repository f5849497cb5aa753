#!/usr/bin/env python3
"""gen-long.py HOURS OUT_PREFIX : a synthetic long drive of the CAT Vehicle (models/paper.toml geometry)
around a 1.3 km stadium loop (two 400 m straights, two 60 m radius half circles) at 8-14 m/s.
Writes OUT_PREFIX.csv (log schema: t,vel,input_vel,accel,steer,brake,lat,lon; reports 50 Hz, GNSS 100 Hz)
and OUT_PREFIX.truth.csv (t,x,y,heading,yaw_rate,speed; rear axle, east/north about 32.2319,-110.9501)."""
import math, random, sys
hours, out = float(sys.argv[1]), sys.argv[2]
L, MAXST, K, ANT = 2.62, math.radians(35.5), 0.0015, 1.478
O = (32.2319, -110.9501); A, F = 6378137.0, 1/298.257223563
lat0 = math.radians(O[0]); e2 = F*(2-F); w = math.sqrt(1-e2*math.sin(lat0)**2)
Mr, Nr = A*(1-e2)/w**3, A/w
def geo(e, n): return O[0]+math.degrees(n/Mr), O[1]+math.degrees(e/(Nr*math.cos(lat0)))
S1, R = 400.0, 60.0; P = 2*S1 + 2*math.pi*R
def curv(s):
    s %= P
    if s < S1 or (S1+math.pi*R) <= s < (2*S1+math.pi*R): return 0.0
    return -1.0/R   # left turns (heading clockwise from north: negative yaw rate)
rng = random.Random(1)
dt = 0.01; T = hours*3600
x = y = 0.0; hd = math.pi/2; s = 0.0; v = 0.0; bias = [0.0, 0.0]
f = open(out+'.csv', 'w'); g = open(out+'.truth.csv', 'w')
f.write('t,vel,input_vel,accel,steer,brake,lat,lon\n'); g.write('t,x,y,heading,yaw_rate,speed\n')
n = int(T/dt); vcmd = 10.0
for i in range(n+1):
    t = i*dt
    if i % 3000 == 0: vcmd = rng.choice([8.0, 10.0, 12.0, 14.0]) if t > 5 else 10.0
    v += (vcmd - v)*dt/1.5
    k = curv(s)
    delta = math.atan(L*k*(1+K*v*v))
    yaw = v*k
    x += v*math.sin(hd)*dt; y += v*math.cos(hd)*dt; hd = (hd + yaw*dt); s += v*dt
    for j in range(2): bias[j] += (-bias[j]/100.0)*dt + 0.8*math.sqrt(2*dt/100.0)*rng.gauss(0, 1)
    row = [f'{t:.2f}', '', '', '', '', '', '', '']
    if i % 2 == 0:
        row[1] = f'{v + rng.gauss(0,0.03):.3f}'; row[2] = f'{vcmd:.2f}'; row[3] = '0'; row[5] = '0'
        row[4] = f'{delta/MAXST*100 + rng.gauss(0,0.2):.2f}'  # + = right
    ae, an = x + ANT*math.sin(hd), y + ANT*math.cos(hd)
    la, lo = geo(ae + bias[0] + rng.gauss(0, 0.3), an + bias[1] + rng.gauss(0, 0.3))
    row[6] = f'{la:.8f}'; row[7] = f'{lo:.8f}'
    f.write(','.join(row) + '\n')
    if i % 2 == 0: g.write(f'{t:.2f},{x:.4f},{y:.4f},{hd % (2*math.pi):.6f},{yaw:.6f},{v:.4f}\n')
