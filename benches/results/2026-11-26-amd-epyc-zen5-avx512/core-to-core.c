// Core-to-core round trip of one cache line, and the rate at which core 0 copies 1 MB that core 1
// has just written. Used for NOTES.md ("Why two threads stay short"). Build and run:
//   gcc -O2 -pthread core-to-core.c -o core-to-core && ./core-to-core
#define _GNU_SOURCE
#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <stdatomic.h>
#include <time.h>
#include <stdlib.h>
#include <string.h>
static _Atomic int flag __attribute__((aligned(64)));
static double now(){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec+t.tv_nsec*1e-9;}
#define N 2000000
static void pin(int c){cpu_set_t s;CPU_ZERO(&s);CPU_SET(c,&s);pthread_setaffinity_np(pthread_self(),sizeof s,&s);}
void*pong(void*a){pin(1);for(int i=0;i<N;i++){while(atomic_load_explicit(&flag,memory_order_acquire)!=2*i+1);atomic_store_explicit(&flag,2*i+2,memory_order_release);}return 0;}
/* bandwidth: thread 1 writes a buffer, thread 0 reads it */
static float *buf,*dst; static _Atomic int phase;
#define M (1<<18)
void*writer(void*a){pin(1);for(int r=0;r<200;r++){while(atomic_load(&phase)!=2*r);for(int i=0;i<M;i++)buf[i]=r+i;atomic_store(&phase,2*r+1);}return 0;}
int main(){
  pin(0); pthread_t t; pthread_create(&t,0,pong,0);
  double s=now(); for(int i=0;i<N;i++){atomic_store_explicit(&flag,2*i+1,memory_order_release);while(atomic_load_explicit(&flag,memory_order_acquire)!=2*i+2);}
  double e=now()-s; pthread_join(t,0);
  printf("round trip %.0f ns\n", e/N*1e9);
  buf=aligned_alloc(64,M*4); memset(buf,0,M*4); dst=aligned_alloc(64,M*4); memset(dst,0,M*4);
  pthread_create(&t,0,writer,0); double rd=0; float acc=0;
  for(int r=0;r<200;r++){while(atomic_load(&phase)!=2*r+1); double s2=now(); memcpy(dst,buf,M*4); acc+=dst[r]; rd+=now()-s2; atomic_store(&phase,2*r+2);}
  pthread_join(t,0);
  printf("read 1 MB written by the other core: %.1f GB/s (%g)\n", 200.0*M*4/rd/1e9, acc>0?1.0:0.0);
}
